"""`sasmi render PRESET --count N --out DIR` and `sasmi sheet DIR`."""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="render a labelled set of chips from a preset",
                       description="Render scenes 0..N-1 of a preset: images/, masks/, labels.jsonl, run.json. "
                                   "Rerunning the same command resumes.")
    p.add_argument("preset", type=Path, help="scene preset (TOML), e.g. scenes/cylinder_chip.toml")
    p.add_argument("--count", type=int, default=16, help="number of scenes (default 16)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="scene i depends only on (seed, i) (default 0)")
    p.add_argument("--workers", type=int, default=1, help="render processes (default 1; Dr.Jit already uses all cores)")
    p.add_argument("--size", type=int, default=256, help="image size in pixels, a multiple of 16 (default 256)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel (default 16)")
    p.add_argument("--format", dest="image_format", choices=["png", "tiff16", "npy"], default="png",
                   help="image format: 8-bit PNG, 16-bit TIFF or float32 NPY (masks are always PNG)")
    p.set_defaults(run=run_render)

    s = sub.add_parser("sheet", help="contact sheet of a folder of chips (with mask outlines for a render set)")
    s.add_argument("folder", type=Path)
    s.add_argument("--out", type=Path, help="PNG to write (default FOLDER_sheet.png beside FOLDER)")
    s.add_argument("--columns", type=int, default=4, help="chips per row (default 4)")
    s.add_argument("--limit", type=int, default=32, help="at most this many chips")
    s.set_defaults(run=run_sheet)


def run_render(args: argparse.Namespace) -> int:
    from sasmi.dataset import RenderJob, render_set
    from sasmi.scene import load_preset

    job = RenderJob(preset=load_preset(args.preset), out=args.out, count=args.count, seed=args.seed,
                    size=args.size, spp=args.spp, image_format=args.image_format, workers=args.workers)
    out = render_set(job)
    print(f"wrote {args.count} chips to {out}")
    return 0


def run_sheet(args: argparse.Namespace) -> int:
    from sasmi.sheet import contact_sheet

    out = contact_sheet(args.folder, args.out, args.columns, args.limit)
    print(f"wrote {out}")
    return 0
