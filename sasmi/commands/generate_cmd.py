"""`sasmi generate PRESET --generator RUN --count N --out DIR`: render and translate, streamed."""
from __future__ import annotations

import argparse
import hashlib
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="render scenes and translate them with a trained SAS GAN, labels kept",
                       description="Render scenes 0..N-1 of a preset and pass each batch through a SAS GAN "
                                   "generator; writes a render set (images/, masks/, labels.jsonl, run.json) whose "
                                   "images are the translations. Rerunning the same command resumes.")
    p.add_argument("preset", type=Path, help="scene preset (TOML)")
    p.add_argument("--generator", type=Path, required=True, metavar="RUN", help="a `sasmi train sasgan` run folder")
    p.add_argument("--count", type=int, default=16)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--size", type=int, default=256, help="render size, a multiple of 16 (default 256)")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--workers", type=int, default=1, help="render processes (default 1)")
    p.add_argument("--batch", type=int, default=16, help="images per generator pass (default 16)")
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from gan.train import load_generator, resolve_device
    from gan.translate import translate
    from sasmi.dataset import RenderJob, render_set
    from sasmi.errors import SasmiError
    from sasmi.scene import load_preset

    if args.batch < 1:
        raise SasmiError(f"--batch: {args.batch} is not allowed (allowed: >= 1)")
    job = RenderJob(preset=load_preset(args.preset), out=args.out, count=args.count, seed=args.seed,
                    size=args.size, spp=args.spp, workers=args.workers).validate()
    generator = load_generator(args.generator, resolve_device(args.device))
    checkpoint = args.generator / "checkpoints" / "last.pt"
    identity = {"generator": str(args.generator.resolve()),
                "generator_sha256": hashlib.sha256(checkpoint.read_bytes()).hexdigest()}
    render_set(job, transform=lambda images: translate(generator, images, args.batch), identity=identity,
               batch=args.batch)
    print(f"wrote {args.count} translated chips with masks and labels to {args.out}")
    return 0
