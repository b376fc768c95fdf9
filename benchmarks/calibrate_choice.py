"""`sasmi calibrate`'s objective of finished presets on other draws of the trials' scenes: what a search's own
measure says of presets, beside the two-sample test (benchmarks/two_sample_seeds.py) that judges them.

    python benchmarks/calibrate_choice.py --real runs/split/train/targets --draws 8 PRESET [PRESET ...]

Each PRESET (a file or a shipped name) renders `--draws` draws of 32 scenes (seeds 100, 101, ...: scenes no search
with a small --seed rendered) scored as a trial is (the default objective), against the real chips; printed: the
mean over the draws of the objective and of its parts, the statistics' term and the φ-FID ratio, and the objective's
spread from draw to draw.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--real", required=True, help="the real chips the presets were calibrated to")
    p.add_argument("--draws", type=int, default=8, help="draws of the trials' scenes (default: 8)")
    p.add_argument("presets", nargs="+", help="preset files or shipped names")
    args = p.parse_args()

    from sasmi.errors import SasmiError
    from sasmi.eval.features import as_encoder
    from sasmi.realism.calibrate import CalibrateConfig, render_chips
    from sasmi.realism.calibration_objective import real_chips, score
    from sasmi.scene.preset import load_preset

    cfg = CalibrateConfig()
    encoder = as_encoder(None)
    try:
        real = real_chips(args.real, encoder, cfg.chips, cfg.size, cfg.seed)
        presets = {name: load_preset(name) for name in args.presets}
    except SasmiError as e:
        print(f"calibrate_choice: {e}", file=sys.stderr)
        return 2
    for name, preset in presets.items():
        parts = np.array([[s["objective"], s["statistics"], s["phi_ratio"]] for s in
                          (score(render_chips(preset, cfg.chips, cfg, 100 + k), real, encoder, cfg.weights())
                           for k in range(args.draws))])
        mean = parts.mean(axis=0)
        print(f"{name}: objective {mean[0]:.3f} (sd {parts[:, 0].std(ddof=1):.3f} a draw), statistics {mean[1]:.3f}, "
              f"φ-FID ratio {mean[2]:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
