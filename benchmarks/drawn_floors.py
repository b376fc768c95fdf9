"""Floors alone: how easily does a small CNN tell synthetic floors from held-back real floor chips?

    python benchmarks/drawn_floors.py --split runs/split [--count 200]

On a split (`sasmi split`), the seabeds of the train floor chips of the target chips' sonar
(as benchmarks/reference_weights.py fits them) make 200 floors each way; each set is judged
against that sonar's validation floor chips by `sasmi evaluate`'s two-sample test (3 repeats):

- drawn: `sasmi generate`'s drawn floors (a drawn seabed under a speckle drawn from the same
  chip's grain and levels);
- render speckle: a `seafloor_only` render's own speckle under the same drawn seabeds (the
  speckle no real sonar made);
- real fresh: `sasmi fit --floors`' floors, one train chip's seabed under another's speckle;
- real train: the train floor chips themselves (the test's floor: near 0.5).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.reference_weights import sonar_floors  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--split", type=Path, required=True, help="a `sasmi split` folder: train/ and validation/")
    p.add_argument("--count", type=int, default=200, help="floors per synthetic set")
    args = p.parse_args()

    from sasmi.eval.config import TwoSampleConfig
    from sasmi.eval.two_sample import resized, two_sample_auc
    from sasmi.images import list_images
    from sasmi.preprocess import load_image
    from sasmi.realism.floors import fresh_floor, gain_bands, seabed_floor
    from sasmi.realism.seabeds import draw_seabed, fit_seabeds, speckle_of
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import load_preset

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        floors = {side: [load_image(f, 128) for f in list_images(sonar_floors(args.split / side, tmp / side))]
                  for side in ("train", "validation")}
        seabeds = fit_seabeds(tmp / "train")
        render_set(RenderJob(preset=load_preset("seafloor_only"), out=tmp / "renders", count=args.count, seed=0,
                             size=128), progress=False)
        renders = [load_image(f, 128).astype(np.float64) for f in list_images(tmp / "renders" / "images")]
    train = floors["train"]
    rng = np.random.default_rng(0)

    def render_speckle(i: int) -> np.ndarray:
        rng_i = np.random.default_rng([0, i])
        seabed = draw_seabed(seabeds, (128, 128), rng_i) * gain_bands(128, rng_i)[:, None]
        return seabed * speckle_of(renders[i])

    sets = {"drawn": [seabed_floor(seabeds, renders[i].shape, 0, i) for i in range(args.count)],
            "render speckle": [render_speckle(i) for i in range(args.count)],
            "real fresh": [fresh_floor(*(train[j] for j in rng.integers(len(train), size=2)), rng)
                           for _ in range(args.count)],
            "real train": train}

    def small(chips) -> np.ndarray:
        return resized((np.clip(np.stack(chips), 0, 1) * 255).astype(np.uint8), 64)

    cfg, real = TwoSampleConfig(repeats=3), small(floors["validation"])
    print(f"{len(floors['validation'])} validation floor chips, {len(train)} train; two-sample ROC AUC (0.5: alike)")
    for name, chips in sets.items():
        t = two_sample_auc(real, small(chips), cfg, 1)
        print(f"{name:15s} {t['auc']:.3f} ± {t['auc_std']:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
