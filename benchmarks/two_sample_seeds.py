"""The two-sample test of several chip sets against one real folder, over several classifier seeds, paired.

    python benchmarks/two_sample_seeds.py --real runs/split/validation/targets --seeds 4 SET [SET ...]

`sasmi evaluate` runs the test once per set: its ROC AUC moves by a few hundredths from one
classifier seed to the next, as much as many changes to a recipe do. Here each seed trains the
same classifier (`sasmi evaluate`'s, at its size) on every set, so two sets are compared on the
same folds and seeds: each set's mean AUC and spread over the seeds, then each set less the first,
with a 95 % interval (normal, over the seeds). A SET is a folder of images or a render set.

Where does the signature lie? `--hide target` sets the band where target chips show their target and
shadow (the middle quarter of the rows, from 5/16 of the range on) to each chip's median in every set and
in the real chips, so that only the floor is judged; `--hide floor` keeps that band alone.

The test's AUC grows with the number of chips it learns from: `--most N` judges each set by N of its chips
drawn at random (the same N on every run), so that sets of different sizes are compared at one size. Not its
first N by name: real chips are named by survey line, and a folder's first lines are not the folder.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def chips_of(folder: Path, size: int) -> np.ndarray:
    """(N, size, size) uint8: a folder's images (a render set's images/) at 128 px, shrunk as the test shrinks them."""
    from sasmi.eval.features import image_paths, load_images, to_pixels
    from sasmi.eval.two_sample import resized

    return resized(to_pixels(load_images(image_paths(folder), 128)), size)


def hidden(chips: np.ndarray, hide: str) -> np.ndarray:
    """(N, S, S) chips with the target band (`--hide target`) or all but it (`--hide floor`) set to each
    chip's median; as they are for `--hide none`."""
    if hide == "none":
        return chips
    s = chips.shape[-1]
    band = np.zeros((s, s), bool)
    band[3 * s // 8:5 * s // 8, 5 * s // 16:] = True  # target chips are cut centred on the target; range grows right
    out = chips.copy()
    out[:, band if hide == "target" else ~band] = np.median(chips, axis=(1, 2))[:, None]
    return out


def drawn(chips: np.ndarray, most: int | None) -> np.ndarray:
    """`most` of the chips, drawn without repeats from a fixed stream, in their order; all of them for None."""
    if most is None or most >= len(chips):
        return chips
    return chips[np.sort(np.random.default_rng(0).choice(len(chips), most, replace=False))]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--real", type=Path, required=True, help="the real chips")
    p.add_argument("--seeds", type=int, default=4, help="classifier seeds (default: 4)")
    p.add_argument("--hide", choices=("none", "target", "floor"), default="none",
                   help="target: judge the floor alone; floor: the target band alone (default: whole chips)")
    p.add_argument("--most", type=int, default=None, metavar="N",
                   help="judge each set by N of its chips drawn at random, the same each run (default: all of them)")
    p.add_argument("sets", type=Path, nargs="+", help="chip sets; the first is the one the others are compared with")
    args = p.parse_args()

    from sasmi.errors import SasmiError
    from sasmi.eval.config import TwoSampleConfig
    from sasmi.eval.two_sample import two_sample_auc

    cfg = TwoSampleConfig()
    if args.most is not None and args.most < 2:
        print(f"two_sample_seeds: --most {args.most}: a set needs at least 2 chips", file=sys.stderr)
        return 2
    try:
        real = hidden(chips_of(args.real, cfg.size), args.hide)
        sets = {str(s): hidden(drawn(chips_of(s, cfg.size), args.most), args.hide) for s in args.sets}
    except SasmiError as e:
        print(f"two_sample_seeds: {e}", file=sys.stderr)
        return 2
    aucs = {name: [] for name in sets}
    for seed in range(args.seeds):
        for name, chips in sets.items():
            aucs[name].append(two_sample_auc(real, chips, cfg, seed=seed)["auc"])
        print(f"seed {seed}: " + ", ".join(f"{n} {a[-1]:.3f}" for n, a in aucs.items()), flush=True)
    first = np.array(aucs[str(args.sets[0])])
    for name, a in aucs.items():
        a = np.array(a)
        line = f"{name}: ROC AUC {a.mean():.3f} (sd {a.std(ddof=1) if len(a) > 1 else 0.0:.3f})"
        if name != str(args.sets[0]) and len(a) > 1:
            d = a - first
            line += f"; less the first {d.mean():+.3f} ± {1.96 * d.std(ddof=1) / np.sqrt(len(d)):.3f} (95 %)"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
