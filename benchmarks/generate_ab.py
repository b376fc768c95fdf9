"""`sasmi generate`'s chips/s at 128² (the shipped files, as `benchmarks/render.py` times it) at another commit and
at this checkout, run in turn, so that a machine whose speed drifts by several per cent from run to run compares
them fairly: the median of the pairs' ratios, and in how many pairs this checkout was faster.

    .venv/bin/python benchmarks/generate_ab.py REV [--pairs 3] [--generate 50 350] [--workers 1]

REV is checked out into a temporary git worktree; both run with this checkout's Python environment
(`python -m sasmi` imports the package of the folder it runs in). --workers N runs this checkout's
`generate --workers N` against REV's one process.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render import REPO, cpu_description, throughput_ms  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("rev", help="the commit to compare with (any git revision)")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--generate", type=int, nargs=2, default=[50, 350], metavar=("SHORT", "LONG"),
                    help="chips of the short and the long run (their difference is timed)")
    ap.add_argument("--workers", type=int, default=1, help="this checkout's `generate --workers` (REV: 1)")
    args = ap.parse_args()
    here = "this checkout" + (f" --workers {args.workers}" if args.workers > 1 else "")
    rates: dict[str, list[float]] = {args.rev: [], here: []}
    with tempfile.TemporaryDirectory() as tmp:
        other = Path(tmp) / "tree"
        added = subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(other), args.rev],
                               capture_output=True, text=True)
        if added.returncode:
            sys.exit(f"generate_ab.py: {args.rev}: cannot check it out ({added.stderr.strip()})")
        try:
            for k in range(args.pairs):
                for name, tree, workers in ((args.rev, other, 1), (here, REPO, args.workers)):
                    rates[name].append(1000 / throughput_ms("generate", workers, 128, *args.generate, repo=tree))
                    print(f"pair {k + 1}, {name}: {rates[name][-1]:.2f} chips/s", flush=True)
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(other)], capture_output=True)
    print(f"machine: {cpu_description()}")
    for name, values in rates.items():
        print(f"{name}: median {statistics.median(values):.2f} chips/s ({', '.join(f'{v:.2f}' for v in values)})")
    ratios = [b / a for a, b in zip(rates[args.rev], rates[here])]
    print(f"{here} / {args.rev}: {statistics.median(ratios):.3f} (median of the pairs' ratios); faster in "
          f"{sum(r > 1 for r in ratios)} of {args.pairs} pairs")


if __name__ == "__main__":
    main()
