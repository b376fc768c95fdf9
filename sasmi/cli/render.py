"""`sasmi render PRESET --count N --out DIR` and `sasmi sheet DIR`."""
from __future__ import annotations

import argparse
import re
from dataclasses import replace
from pathlib import Path


MAX_SHARDS = 100_000  # one process per scene at the largest --count


def shard_spec(text: str) -> tuple[int, int]:
    """--shard I/N: 0 <= I < N <= MAX_SHARDS."""
    match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not match:
        raise argparse.ArgumentTypeError(f"{text!r} is not I/N (allowed: e.g. 0/4, with 0 <= I < N)")
    i, n = int(match[1]), int(match[2])
    if not 0 <= i < n <= MAX_SHARDS:
        raise argparse.ArgumentTypeError(f"{text!r} is out of range (allowed: I/N with 0 <= I < N <= {MAX_SHARDS})")
    return i, n


def scheduler_address(text: str) -> str:
    if not re.fullmatch(r"(tcp|tls|ws|wss|ucx)://(\[[0-9a-fA-F:]+\]|[^\s/:\[\]]+)(:\d{1,5})?/?|[^\s/:]+:\d{1,5}", text):
        raise argparse.ArgumentTypeError(f"{text!r} is not a scheduler address (allowed: tcp://HOST:PORT)")
    return text


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="render a labelled set of chips from a preset",
                       description="Render scenes 0..N-1 of a preset: images/, masks/, labels.jsonl, run.json "
                                   "(or WebDataset tar shards with --format wds). Rerunning the same command "
                                   "resumes; any number of processes may render into one --out at once "
                                   "(each chip is claimed first), e.g. one per --shard.")
    p.add_argument("preset", type=Path, help="scene preset (TOML), e.g. scenes/cylinder_chip.toml")
    p.add_argument("--count", type=int, default=16, help="number of scenes")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="scene i depends only on (seed, i)")
    p.add_argument("--workers", type=int, default=1,
                   help="processes on this machine, each rendering every N-th of this command's scenes on "
                        "cores // N Dr.Jit threads (default: 1; on 2 cores 2 render a 256 px chip in 0.8-0.9 × "
                        "the time of one: docs/scale.md)")
    p.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="render on the workers of this running Dask cluster (they write into --out, which must be "
                        "on a filesystem they share); see docs/scale.md for SLURM/PBS")
    p.add_argument("--shard", type=shard_spec, default=(0, 1), metavar="I/N",
                   help="render only scenes with index %% N == I (with --format wds: tar shards k %% N == I); "
                        "run N such processes, anywhere, on one --out (default: 0/1: all)")
    p.add_argument("--size", type=int, default=256, help="image size in pixels, a multiple of 16")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel")
    p.add_argument("--format", dest="image_format", choices=["png", "tiff16", "npy", "wds"], default="png",
                   help="image format: 8-bit PNG, 16-bit TIFF or float32 NPY (masks are always PNG); wds: "
                        "WebDataset tar shards shards/shard-NNNNNN.tar of 8-bit PNGs, masks and JSON labels")
    p.add_argument("--per-shard", type=int, default=1000,
                   help="samples per tar shard with --format wds (default: 1000)")
    p.set_defaults(run=run_render)

    s = sub.add_parser("sheet", help="contact sheet of a folder of chips (with mask outlines for a render set)")
    s.add_argument("folders", type=Path, nargs="+", metavar="FOLDER",
                   help="a folder of chips; with several (renders, then their translations), each tile shows the "
                        "same-named chip of each side by side, then the last one's mask outline")
    s.add_argument("--out", type=Path, help="PNG to write (default: FOLDER_sheet.png beside FOLDER)")
    s.add_argument("--columns", type=int, default=4, help="chips per row")
    s.add_argument("--limit", type=int, default=32, help="at most this many chips")
    s.set_defaults(run=run_sheet)


def run_render(args: argparse.Namespace) -> int:
    from sasmi.renderset.write import RenderJob, missing, prepare
    from sasmi.scene.preset import load_preset
    from sasmi.renderset.shards import complete_samples, missing_shards

    job = RenderJob(preset=load_preset(args.preset), out=args.out, count=args.count, seed=args.seed,
                    size=args.size, spp=args.spp, image_format=args.image_format, workers=args.workers,
                    shard=args.shard, scheduler=args.scheduler, per_shard=args.per_shard).validate()
    if job.workers > 1:  # whole processes, each a share of this one's scenes (sasmi.renderset.processes)
        from functools import partial

        from sasmi.renderset.processes import complete_chips, run_shares

        prepare(job)  # every scene checked and run.json written before any process starts
        done = (partial(complete_chips, job.out, job.shard) if job.image_format != "wds" else
                partial(complete_samples, job))
        run_shares(partial(_render_share, replace(job, workers=1)), job.workers, done, len(job.indices()), "render")
    else:
        _render(job)
    if job.image_format == "wds":
        left, unit = missing_shards(job), "tar shards"
    else:
        left, unit = missing(job.out, job.count, job.image_format), "chips"
    if not left:
        print(f"wrote {args.count} chips to {job.out}")
    else:  # other processes hold them, or (--shard) they are another shard's
        print(f"rendered this process's share into {job.out}; {len(left)} {unit} of {args.count} chips are not "
              "complete yet (other shards or processes; rerun the same command to finish any left by a dead one)")
    return 0


def _render(job, progress: bool = True) -> None:
    from sasmi.renderset.shards import render_shards
    from sasmi.renderset.write import render_set

    if job.image_format == "wds":
        render_shards(job, progress=progress)
    else:
        render_set(job, progress=progress)


def _render_share(job, share: int, shares: int) -> None:
    """One process of `--workers N`: share k of N of the job's --shard I/M, i.e. --shard (I + k M)/(N M),
    on cores // N Dr.Jit threads."""
    from sasmi.renderset.processes import in_share
    from sasmi.renderset.threads import local_threads

    i, m = job.shard
    in_share("render", local_threads(shares), lambda: _render(replace(job, shard=(i + share * m, m * shares)),
                                                              progress=False))


def run_sheet(args: argparse.Namespace) -> int:
    from sasmi.renderset.sheet import contact_sheet

    out = contact_sheet(args.folders[-1], args.out, args.columns, args.limit, before=tuple(args.folders[:-1]))
    print(f"wrote {out}")
    return 0
