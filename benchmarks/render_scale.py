"""Chips/s of `sasmi render` in one process vs `--workers N` processes.

Each configuration runs the real CLI in a fresh subprocess into a fresh folder, so the
figures include everything a user waits for. Two rates per run:
- overall: chips / wall time of the command (interpreter, process starts, kernel compile);
- steady: (chips - 1) / (time between the first and the last chip's labels file), i.e. the
  rate once every worker is warm (what matters for large sets).

    .venv/bin/python benchmarks/render_scale.py [--count 40] [--size 128] [--spp 16] [--workers 1 2]
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PRESET = REPO / "scenes" / "cylinder_chip.toml"  # 32 emitters


def run(workers: int, count: int, size: int, spp: int) -> tuple[float, float]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "set"
        command = [sys.executable, "-m", "sasmi.cli.main", "render", str(PRESET), "--out", str(out), "--count",
                   str(count), "--size", str(size), "--spp", str(spp), "--workers", str(workers)]
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True, env={**os.environ, "PYTHONPATH": str(REPO)})
        wall = time.perf_counter() - start
        stamps = sorted(p.stat().st_mtime for p in (out / "labels").glob("*.json"))
    return count / wall, (count - 1) / (stamps[-1] - stamps[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--count", type=int, default=40)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    print(f"{platform.node()}: {os.cpu_count()} cores; {args.count} chips of {PRESET.name} at {args.size} px, "
          f"{args.spp} spp (32 emitters)")
    print(f"{'workers':>8} {'overall chips/s':>16} {'steady chips/s':>15}")
    for workers in args.workers:
        overall, steady = run(workers, args.count, args.size, args.spp)
        print(f"{workers:>8} {overall:>16.2f} {steady:>15.2f}")


if __name__ == "__main__":
    main()
