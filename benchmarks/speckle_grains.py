"""Do a drawn speckle's bright pixels come in grains, as a real floor's do?

    python benchmarks/speckle_grains.py --seabeds runs/shipped-recipe/train/weights/seabeds.pt \
        --real runs/split/train/targets [--draws 150]

A coherent sonar's intensity is |z|² of a complex field: its bright pixels come in grains, a
neighbour of a bright pixel often bright too. IAAFT (sasmi.realism.seabeds) keeps a speckle's
spectrum and gray levels, not that; started from shuffled levels, its bright pixels stand alone
among dim ones, which a small classifier sees. Per chip, in the rows clear of the target (those
the seabeds take the speckle from), this prints the medians of

- isolated bright pixels: the brightest of their 5 × 5 neighbourhood and over 3 × its 9-px median;
- grains: the correlation of neighbouring pixels' squared deviations along range;

for the real chips' speckle (chip over seabed), a drawn speckle started from a coherent speckle
(as `sasmi generate` draws it), one started from shuffled levels, and whole drawn floors.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage


def isolated(x: np.ndarray, rows: np.ndarray) -> int:
    peak = (x == ndimage.maximum_filter(x, 5)) & (x > 3 * ndimage.median_filter(x, 9))
    return int(peak[rows].sum())


def grains(x: np.ndarray, rows: np.ndarray) -> float:
    d = (x[rows] - x[rows].mean()) ** 2
    d = d - d.mean()
    return float((d[:, 1:] * d[:, :-1]).mean() / max((d * d).mean(), 1e-300))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seabeds", type=Path, required=True, help="a seabeds file (benchmarks/reference_weights.py)")
    p.add_argument("--real", type=Path, required=True, help="real target chips (their floors' speckle)")
    p.add_argument("--draws", type=int, default=150, help="drawn speckles and floors per kind")
    args = p.parse_args()

    from sasmi.errors import SasmiError
    from sasmi.images import list_images
    from sasmi.preprocess import load_image
    from sasmi.realism.seabeds import SPECKLE, TARGET_ROWS, draw_floor, draw_speckle, load_seabeds, speckle_of

    try:
        seabeds = load_seabeds(args.seabeds)
        paths = list_images(args.real)
        if not paths:
            raise SasmiError(f"--real {args.real}: no image (png, jpg, tif, tiff, npy) in it")
        real = [speckle_of(load_image(path, SPECKLE).astype(np.float64)) for path in paths]
    except SasmiError as e:
        print(f"speckle_grains: {e}", file=sys.stderr)
        return 2
    rows = np.r_[0:SPECKLE // 2 - TARGET_ROWS, SPECKLE // 2 + TARGET_ROWS:SPECKLE]

    def drawn(make) -> list[np.ndarray]:
        rng = np.random.default_rng(0)
        return [make(rng) for _ in range(args.draws)]

    chips = len(seabeds.speckle_levels)
    sets = {
        "real floors' speckle": real,
        "drawn speckle, coherent start": drawn(lambda rng: draw_speckle(seabeds, int(rng.integers(chips)), rng)),
        "drawn speckle, shuffled start": drawn(lambda rng: draw_speckle(seabeds, int(rng.integers(chips)), rng,
                                                                        coherent=False)),
        "drawn floors": drawn(lambda rng: draw_floor(seabeds, (SPECKLE, SPECKLE), rng)),
    }
    for name, chips_of_set in sets.items():
        print(f"{name:30s} isolated bright pixels {np.median([isolated(x, rows) for x in chips_of_set]):5.1f}"
              f"   grains {np.median([grains(x, rows) for x in chips_of_set]):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
