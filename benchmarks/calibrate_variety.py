"""Where a set of renders lacks the real chips' variety: along the real chips' main φ directions, or off them.

The real chips' 8 principal directions in φ carry what varies most from chip to chip (on the shared MILCO
targets: mean level, range fall-off, the scene's scale in pixels). For each folder of renders: its sd along each
direction over the real chips' (1: as varied), the mean log² of those ratios, its sd off the directions (the rest
of φ's 1024 dimensions) over the real chips', and recall (the share of the real chips near some render in φ, k = 3,
as `sasmi calibrate` scores a trial) of 32 renders against the real chips, averaged over 16 draws; the real chips'
own recall is that of 32 of them against the others. The real chips' sd is measured on chips outside the directions'
fit (10 folds), as renders are: the chips that fit a direction spread more along it than any others do.

    .venv/bin/python benchmarks/calibrate_variety.py REAL [RENDERS ...] [--phi RUN/phi] [--sheet PNG] [--moves PRESET]

--sheet PNG draws what the first directions are: a row each, the 6 real chips lowest along it | the 6 highest.
--moves PRESET tells which of a preset's fields move its chips along them: 48 renders of the preset (the same scenes
each time), and of it with each knob of `sasmi calibrate` halved and doubled, their mean moved along each of the first
3 directions, in the real chips' sd along it: a field that moves the chips along a direction the preset spans too
little is the one whose spread to widen. Its last column draws each field over its centre x (1 ± 0.5) instead (its
spread in parentheses): the 48 chips' sd off the main directions over the real chips', and their recall against the
real chips (48 renders; compare with the preset's own, printed above the table).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

AXES = 8
CHIPS = 32  # a trial's renders
DRAWS = 16
FOLDS = 10
SHEET_ROWS, SHEET_ENDS = 3, 6
MOVE_CHIPS = 48  # renders a setting of --moves
WIDE = 0.5  # --moves: a field drawn over its centre x (1 ± WIDE)


def main_directions(phi: np.ndarray) -> np.ndarray:
    """(AXES, D): the principal directions of a set of chips in φ."""
    return np.linalg.svd(phi - phi.mean(0), full_matrices=False)[2][:AXES]


def along_and_off(centred: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each chip's place along the directions, and its squared distance off them."""
    projected = centred @ axes.T
    return projected, (centred ** 2).sum(1) - (projected ** 2).sum(1)


def held_out_spread(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The real chips' main directions, and their sd along them and off them as chips outside the fit see them."""
    along, off = [], []
    for fold in np.array_split(np.random.default_rng(0).permutation(len(phi)), FOLDS):
        fit = phi[np.setdiff1d(np.arange(len(phi)), fold)]
        projected, off_squared = along_and_off(phi[fold] - fit.mean(0), main_directions(fit))
        along.append(projected)
        off.append(off_squared)
    return (main_directions(phi), np.sqrt(np.mean(np.concatenate(along) ** 2, axis=0)),
            float(np.sqrt(np.concatenate(off).mean())))


def write_sheet(images: np.ndarray, along: np.ndarray, path: Path) -> None:
    from PIL import Image

    rows = []
    for d in range(SHEET_ROWS):
        order = np.argsort(along[:, d])
        ends = [*order[:SHEET_ENDS], *order[-SHEET_ENDS:]]
        rows.append(np.concatenate([images[i] for i in ends], axis=1))
    Image.fromarray(np.round(np.concatenate(rows) * 255).astype(np.uint8)).save(path)
    print(f"wrote {path}: a row per direction (1-{SHEET_ROWS}), its {SHEET_ENDS} lowest real chips | its "
          f"{SHEET_ENDS} highest")


def spread(x: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    projected, off_squared = along_and_off(x - x.mean(0), axes)
    return projected.std(0, ddof=1), float(np.sqrt(off_squared.sum() / (len(x) - 1)))


def main() -> None:
    from sasmi.eval.features import as_encoder, image_paths, load_images, phi_features
    from sasmi.eval.manifold import precision_recall

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("real", help="the real chips the renders were matched to")
    ap.add_argument("renders", nargs="*", help="folders of renders, or of real chips kept out (more than 32 each)")
    ap.add_argument("--phi", help="φ run folder or checkpoint (default: the shipped φ)")
    ap.add_argument("--sheet", type=Path, metavar="PNG", help="write the real chips at each end of the first "
                                                              f"{SHEET_ROWS} directions here")
    ap.add_argument("--moves", metavar="PRESET", help="which of this preset's fields move its chips along the first "
                                                      f"{SHEET_ROWS} directions")
    args = ap.parse_args()

    encoder = as_encoder(args.phi)

    def chips(folder: str) -> np.ndarray:
        paths = image_paths(folder)
        if len(paths) < CHIPS + 1:
            sys.exit(f"{folder}: {len(paths)} chips; at least {CHIPS + 1} needed")
        return load_images(paths, 128)

    def features(folder: str) -> np.ndarray:
        return phi_features(encoder, chips(folder)).astype(np.float64)

    real_images = chips(args.real)
    real = phi_features(encoder, real_images).astype(np.float64)
    axes, real_along, real_off = held_out_spread(real)
    if args.sheet:
        write_sheet(real_images, (real - real.mean(0)) @ axes.T, args.sheet)
    rng = np.random.default_rng(0)
    own = np.mean([precision_recall(real[o[CHIPS:]], real[o[:CHIPS]])[1]
                   for o in (rng.permutation(len(real)) for _ in range(DRAWS))])
    print(f"{len(real)} real chips of {args.real}; their sd along the {AXES} main φ directions "
          f"{', '.join(f'{v:.2f}' for v in real_along)}, off them {real_off:.2f}; recall of {CHIPS} of them "
          f"against the others {own:.2f}")
    print(f"| renders | sd along the {AXES} main directions ÷ real | mean log² | sd off them ÷ real | "
          f"recall, {CHIPS} against the real chips |")
    print("|---|---|---|---|---|")
    for folder in args.renders:
        x = features(folder)
        along, off = spread(x, axes)
        ratio = along / real_along
        draws = np.random.default_rng(1)  # the same draws for each set, wherever it stands in the list
        recall = np.mean([precision_recall(real, x[draws.permutation(len(x))[:CHIPS]])[1] for _ in range(DRAWS)])
        print(f"| {folder} | {' '.join(f'{r:.2f}' for r in ratio)} | {np.mean(np.log(ratio) ** 2):.2f} | "
              f"{off / real_off:.2f} | {recall:.2f} |")
    if args.moves:
        moves(args.moves, lambda images: phi_features(encoder, images).astype(np.float64), real, axes, real_along,
              real_off)


def moves(name: str, features, real: np.ndarray, axes: np.ndarray, real_along: np.ndarray, real_off: float) -> None:
    """For each knob, the preset's chips' mean moved along the first directions as the knob is halved and doubled,
    and their spread off the main directions and recall with the knob drawn over centre x (1 ± WIDE)."""
    from sasmi.errors import SasmiError
    from sasmi.eval.manifold import precision_recall
    from sasmi.realism.calibrate import CalibrateConfig, render_chips
    from sasmi.realism.preset_space import KNOBS, apply, start_values
    from sasmi.scene.preset import Preset, load_preset

    preset = load_preset(name)
    knobs = tuple(k for k in KNOBS if not k.startswith("targets."))
    start = start_values(preset.raw, knobs)
    widths = start_values(preset.raw, tuple(f"{k}.spread" for k in knobs))

    def measure(raw: dict) -> tuple[np.ndarray, float, float]:
        x = features(render_chips(Preset.from_dict(raw, path=preset.path), MOVE_CHIPS, CalibrateConfig(), seed=3))
        mean_along = ((x - real.mean(0)) @ axes[:SHEET_ROWS].T / real_along[:SHEET_ROWS]).mean(0)
        return mean_along, spread(x, axes)[1] / real_off, precision_recall(real, x)[1]

    def cell(raw_of) -> tuple[str, str]:
        try:
            along, off, recall = measure(raw_of())
        except SasmiError as e:  # a setting that breaks a rule of the preset in some scene
            return (f"invalid ({e})",) * 2
        return " ".join(f"{m:+.2f}" for m in along - base), f"{off:.2f}, {recall:.2f}"

    base, base_off, base_recall = measure(preset.raw)
    print(f"\n{name}: its {MOVE_CHIPS} chips' mean along directions 1-{SHEET_ROWS} "
          f"{' '.join(f'{b:+.2f}' for b in base)} (real sd), sd off the {AXES} directions {base_off:.2f} of the "
          f"real chips', recall {base_recall:.2f}; moved by")
    print(f"| field | start (spread) | halved | doubled | drawn over ± {WIDE:g}: sd off ÷ real, recall |")
    print("|---|---|---|---|---|")
    for knob in knobs:
        if start[knob] == 0:
            continue  # halved, doubled or drawn around it, still none
        halved, _ = cell(lambda: apply(preset.raw, {knob: start[knob] * 0.5}))
        doubled, _ = cell(lambda: apply(preset.raw, {knob: start[knob] * 2.0}))
        _, wide = cell(lambda: apply(preset.raw, {f"{knob}.spread": WIDE}))
        print(f"| {knob} | {start[knob]:.3g} ({widths[knob + '.spread']:.2f}) | "
              f"{halved} | {doubled} | {wide} |")


if __name__ == "__main__":
    main()
