"""`sasmi translate`: renders → realistic-looking images with a trained SAS GAN generator."""
from __future__ import annotations

import argparse
from pathlib import Path

from sasmi.cli.common import add_translation_flags, generator_from


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("translate", help="make renders look real with a trained SAS GAN generator",
                              description="Output mirrors the input names as PNG; a render set's masks/ and "
                                          "labels.jsonl are copied so its labels still apply.")
    p.add_argument("--in", dest="in_dir", required=True, metavar="DIR", help="a render set or a folder of images")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_translation_flags(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    generator = generator_from(args)
    from sasmi.gan.translate import translate_folder

    n = translate_folder(generator, args.in_dir, args.out, args.batch,
                         provenance={"generator": str(Path(args.generator).resolve()),
                                     "checkpoint": str(generator.checkpoint)})
    print(f"sasmi translate: {n} images → {args.out}")
    return 0
