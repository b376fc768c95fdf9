"""`sasmi generate PRESET --generator RUN --count N --out DIR`: render and translate, streamed.

Render scenes 0..N-1 of a preset and pass each batch through a SAS GAN generator; writes a render
set (images/, masks/, labels.jsonl, run.json) whose images are the translations. Rerunning the same
command resumes.
"""
from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from sasmi.commands.common import add_translation_flags, generator_from


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("generate", help="render scenes and translate them with a trained SAS GAN, labels kept",
                       description=__doc__)
    p.add_argument("preset", type=Path, help="scene preset (TOML)")
    p.add_argument("--count", type=int, default=16, help="number of scenes (default 16)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--seed", type=int, default=0, help="scene i depends only on (seed, i) (default 0)")
    p.add_argument("--size", type=int, help="render size, a multiple of 16 (default: the size the generator "
                                            "was trained at; another size is resampled to it and back)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel (default 16)")
    p.add_argument("--workers", type=int, default=1, help="render processes (default 1)")
    add_translation_flags(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.dataset import RenderJob, render_set
    from sasmi.scene import load_preset

    preset = load_preset(args.preset)
    generator = generator_from(args)
    from sasmi.gan.translate import translate
    job = RenderJob(preset=preset, out=args.out, count=args.count, seed=args.seed,
                    size=args.size or generator.image_size, spp=args.spp, workers=args.workers).validate()
    identity = {"generator": str(Path(args.generator).resolve()),
                "generator_sha256": hashlib.sha256(generator.checkpoint.read_bytes()).hexdigest()}
    # a tone style's code per chip from (--seed, scene index), as its scene: the same in any batch or worker
    render_set(job, transform=lambda images, indices: translate(generator, images, args.batch,
                                                                 seeds=[args.seed * 2 ** 32 + i for i in indices]),
               identity=identity, batch=args.batch)
    print(f"wrote {args.count} translated chips ({job.size} px) with masks and labels to {args.out}")
    return 0
