"""Two `sasmi atr-bench` runs on the same real chips, paired seed by seed: each arm's (real chips per class, way)
mean ROC AUC in each run, and the second run's difference from the first in ROC AUC and Pd, with its 95 % interval
(Student's t over the seeds both ran). A seed draws the same real chips and initialises the same network in every
run of the bench, so the difference is the synthetic chips' alone (the `real` arms differ by exactly 0).

    python benchmarks/atr_paired.py RUN_A/bench RUN_B/bench
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from sasmi.atr.bench import read_runs
from sasmi.atr.summary import interval


def runs(folder: Path) -> dict[tuple[str, str, int], dict]:
    """{(real per class, way, seed): run} of the bench in FOLDER."""
    return read_runs(folder / "runs.jsonl")[1]


def _mean_and_interval(values: list[float]) -> tuple[float, float, float]:
    """Mean and its 95 % interval (Student's t over the seeds, as the bench's own tables)."""
    m = interval(values)
    return m["mean"], m["mean"] - m["ci95"], m["mean"] + m["ci95"]


def paired(first: dict, second: dict) -> list[dict]:
    """Per (real per class, way) both runs hold for 2 seeds or more: the two mean AUCs and the second's differences."""
    out = []
    for n, way in dict.fromkeys((n, way) for n, way, _ in first):
        seeds = sorted(s for k, w, s in first if (k, w) == (n, way) and (n, way, s) in second)
        if len(seeds) < 2:
            continue
        a, b = ([run[(n, way, s)] for s in seeds] for run in (first, second))
        difference = {m: _mean_and_interval([y[m] - x[m] for x, y in zip(a, b)]) for m in ("auc", "pd")}
        means = {"auc_first": float(np.mean([x["auc"] for x in a])),
                 "auc_second": float(np.mean([y["auc"] for y in b]))}
        out.append({"n": n, "way": way, "seeds": len(seeds), **means, **{f"d_{m}": d for m, d in difference.items()}})
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("first", type=Path, help="an atr-bench --out folder")
    parser.add_argument("second", type=Path, help="another, on the same real chips")
    args = parser.parse_args(argv)
    try:
        rows = paired(runs(args.first), runs(args.second))
    except OSError as e:
        print(f"atr_paired: error: {e.filename}: {e.strerror}", file=sys.stderr)
        return 2
    except KeyError as e:
        print(f"atr_paired: error: {args.first} or {args.second}: not runs.jsonl of `sasmi atr-bench` ({e})",
              file=sys.stderr)
        return 2
    if not rows:
        print(f"atr_paired: error: {args.first} and {args.second} share no arm of 2 seeds or more", file=sys.stderr)
        return 2
    print(f"| real chips per class | way | seeds | ROC AUC, {args.first} | {args.second} | Δ ROC AUC | Δ Pd |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for r in rows:
        d = {m: "{:+.3f} [{:+.3f}, {:+.3f}]".format(*r[f"d_{m}"]) for m in ("auc", "pd")}
        print(f"| {r['n']} | {r['way']} | {r['seeds']} | {r['auc_first']:.3f} | {r['auc_second']:.3f} | {d['auc']} "
              f"| {d['pd']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
