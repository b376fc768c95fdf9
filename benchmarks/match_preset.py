"""Match a preset to real chips: render it, then `sasmi stats` against the real folder with tolerances.

Renders PRESET at --size (default 128) into --out (resumes: an existing set with the same
job is reused), computes the mask-free image statistics of the real folder and of the
renders, and prints the side-by-side table with ok/FAIL per statistic (the tolerances of
docs/matching.md) and a summary line `pass=K/N`. Exit status 0 when every statistic passes.

    .venv/bin/python benchmarks/match_preset.py scenes/cylinder_chip.toml --real SPLIT/train/targets \
        --count 150 --out runs/match/cylinder [--also scenes/muscle_paper.toml=runs/match/muscle]

Tune on train chips only and report on validation chips (`sasmi split`), so that the match
is not a fit to the chips it is judged on.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def render(preset: Path, out: Path, count: int, size: int, spp: int, seed: int) -> Path:
    """Render (or resume) the set; prints the wall time per chip rendered by this call."""
    import time

    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.images import list_images
    from sasmi.scene.preset import load_preset

    before = len(list_images(out)) if out.is_dir() else 0
    start = time.perf_counter()
    path = render_set(RenderJob(preset=load_preset(preset), out=out, count=count, seed=seed, size=size, spp=spp))
    if count > before:
        ms = (time.perf_counter() - start) / (count - before) * 1000
        print(f"preset={preset} rendered={count - before} size={size} spp={spp} ms_per_chip={ms:.0f} "
              "(wall time, process start and kernel compile included)")
    return path


def side_by_side(folders: list[Path], names: list[str], path: Path, size: int, columns: int) -> None:
    """One row of the first `columns` chips of each folder, labelled on the left."""
    import numpy as np
    from matplotlib.figure import Figure

    from sasmi.images import atomic_path, list_images
    from sasmi.preprocess import load_image

    fig = Figure(figsize=(columns * 1.3 + 0.9, len(folders) * 1.3))
    axes = fig.subplots(len(folders), 1, squeeze=False)[:, 0]
    for ax, folder, name in zip(axes, folders, names):
        row = [load_image(p, size) for p in list_images(folder)[:columns]]
        gap = np.ones((size, 4), dtype=np.float32)
        ax.imshow(np.concatenate([x for chip in row for x in (chip, gap)][:-1], axis=1), cmap="gray", vmin=0, vmax=1)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_ylabel(name, fontsize=9)
    fig.subplots_adjust(left=0.04, right=0.995, top=0.99, bottom=0.01, hspace=0.05)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("preset", type=Path)
    p.add_argument("--real", type=Path, required=True, help="real chips to match (train targets when tuning)")
    p.add_argument("--out", type=Path, required=True, help="render folder (reused when it exists)")
    p.add_argument("--also", action="append", default=[], metavar="PRESET=DIR",
                   help="another preset to render and show beside it (e.g. the preset before tuning)")
    p.add_argument("--count", type=int, default=150)
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--plot", type=Path, help="histograms of the statistics (PNG)")
    p.add_argument("--figure", type=Path, help="side by side (PNG): a row of real chips, then a row per preset")
    p.add_argument("--columns", type=int, default=8, help="chips per row of --figure")
    args = p.parse_args(argv)

    from sasmi.chips.stats import chip_statistics
    from sasmi.chips.compare import TOLERANCES, check, plot, table

    jobs = [(args.preset, args.out)] + [tuple(Path(x) for x in spec.split("=", 1)) for spec in args.also]
    results = [chip_statistics(args.real, args.size)]
    for preset, out in jobs:
        render(preset, out, args.count, args.size, args.spp, args.seed)
        results.append(chip_statistics(out, args.size))
    print(table(results, with_check=True))
    for (preset, _), r in zip(jobs, results[1:]):
        ok = check(results[0], r)
        print(f"preset={preset} pass={sum(ok.values())}/{len(TOLERANCES)} failed={','.join(k for k, v in ok.items() if not v) or '-'}")
    if args.plot:
        plot(results, args.plot)
    if args.figure:
        side_by_side([args.real] + [out for _, out in jobs], ["real"] + [p.stem for p, _ in jobs], args.figure,
                     args.size, args.columns)
    return 0 if all(check(results[0], results[1]).values()) else 1


if __name__ == "__main__":
    sys.exit(main())
