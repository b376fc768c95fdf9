"""What a finished `sasmi calibrate` search traded for its φ-FID ratio: recall on the search's scenes, trial by trial.

Every trial of RUN/study.db keeps its φ-FID ratio and recall (the share of the real chips near some render in φ).
Printed: the start preset's (trial 0), the mean over the best tenth of the trials by objective, and the mean and
highest recall of the trials in each band of φ-FID ratio: whether the settings nearest the real chips in φ are
also the ones whose chips are alike.

    .venv/bin/python benchmarks/calibrate_trials.py RUN [RUN ...]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

BANDS = ((0.0, 1.2), (1.2, 1.4), (1.4, 1.7), (1.7, 2.5))


def main() -> None:
    import optuna

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="`sasmi calibrate` run folders")
    args = ap.parse_args()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    print("| run | trials | start: ratio / recall | best tenth: ratio / recall | "
          + " | ".join(f"ratio {lo:g}-{hi:g}: trials, recall mean / max" for lo, hi in BANDS) + " |")
    print("|---|---|---|---|" + "---|" * len(BANDS))
    for run in args.runs:
        try:
            study = optuna.load_study(study_name="calibrate", storage=f"sqlite:///{run}/study.db")
        except KeyError:
            sys.exit(f"{run}/study.db: no calibration study")
        trials = [t for t in study.trials if t.value is not None and "recall" in t.user_attrs]
        value = np.array([t.value for t in trials])
        ratio = np.array([t.user_attrs["phi_ratio"] for t in trials])
        recall = np.array([t.user_attrs["recall"] for t in trials])
        best = value <= np.quantile(value, 0.1)
        cells = []
        for lo, hi in BANDS:
            band = (ratio >= lo) & (ratio < hi)
            cells.append(f"{band.sum()}, {recall[band].mean():.2f} / {recall[band].max():.2f}" if band.any() else "0")
        print(f"| {run} | {len(trials)} | {ratio[0]:.2f} / {recall[0]:.2f} | {ratio[best].mean():.2f} / "
              f"{recall[best].mean():.2f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
