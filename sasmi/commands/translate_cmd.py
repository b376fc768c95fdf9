"""`sasmi translate`: renders → realistic-looking images with a trained SAS GAN generator."""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("translate", help="make renders look real with a trained SAS GAN generator",
                              description="Output mirrors the input names as PNG; a render set's masks/ and "
                                          "labels.jsonl are copied so its labels still apply.")
    p.add_argument("--generator", required=True, metavar="RUN", help="a `sasmi train sasgan` run folder")
    p.add_argument("--in", dest="in_dir", required=True, metavar="DIR", help="a render set or a folder of images")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--batch", type=int, default=16, help="images per forward pass (default 16)")
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from gan.train import load_generator, resolve_device
    from gan.translate import translate_folder
    from sasmi.errors import SasmiError

    if args.batch < 1:
        raise SasmiError(f"--batch {args.batch}: must be positive")
    generator = load_generator(args.generator, resolve_device(args.device))
    n = translate_folder(generator, args.in_dir, args.out, args.batch,
                         provenance={"generator": str(Path(args.generator).resolve())})
    print(f"sasmi translate: {n} images → {args.out}")
    return 0
