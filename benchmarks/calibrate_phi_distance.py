"""Why the plain φ-FID of a few renders favours renders that are too alike, and what `sasmi calibrate` scores instead.

A trial scores 32 renders against the real chips. Here 32 real chips stand in for the renders: drawn at
random from the real folder, their φ pulled towards the real chips' mean by a factor (1: as they are, 0.8 and 0.6:
less varied, 1.25: more), then scored against the other real chips by the plain φ-FID, by the objective's
spread-corrected φ-FID (`spread_corrected_fid` of sasmi/realism/calibration_objective.py, its reference drawn from
the same other chips) and by the unbiased KID of `sasmi evaluate` (32 against 32 others). A distance that does not reward
narrowness rises below 1; one useful to a search also moves by more than its spread from one draw to the next.

    .venv/bin/python benchmarks/calibrate_phi_distance.py runs/split/train/targets [--phi RUN/phi] [--draws 60]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CHIPS = 32  # a trial's renders (`sasmi calibrate --chips`)
FACTORS = (1.0, 0.8, 0.6, 1.25)


def main() -> None:
    from sasmi.eval.features import as_encoder, image_paths, load_images, phi_features
    from sasmi.eval.metrics import fid, mmd2_unbiased
    from sasmi.realism.calibration_objective import half_split_fid, spread_corrected_fid

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("real", help="a folder of real chips (at least 96)")
    ap.add_argument("--phi", help="φ run folder or checkpoint (default: the shipped φ)")
    ap.add_argument("--draws", type=int, default=60, help="random draws of the 32 chips per factor")
    args = ap.parse_args()

    phi = phi_features(as_encoder(args.phi), load_images(image_paths(args.real), 128)).astype(np.float64)
    if len(phi) < 3 * CHIPS:
        sys.exit(f"{args.real}: {len(phi)} chips; at least {3 * CHIPS} needed")
    rng = np.random.default_rng(0)
    centre = phi.mean(0)
    rows = {}
    for factor in FACTORS:
        fids, corrected, kids = [], [], []
        for _ in range(args.draws):
            order = rng.permutation(len(phi))
            drawn, rest = phi[order[:CHIPS]], phi[order[CHIPS:]]
            # the objective's real side, from the other chips alone: `real_chips` with `rest` as the folder
            firsts = [rest[rng.permutation(len(rest))[:CHIPS]] for _ in range(4)]
            halves = float(np.mean([half_split_fid(f) for f in firsts]))
            drawn = centre + factor * (drawn - centre)
            fids.append(fid(drawn, rest))
            corrected.append(spread_corrected_fid(drawn, rest, halves))
            kids.append(mmd2_unbiased(drawn, rest[rng.choice(len(rest), CHIPS, replace=False)]))
        rows[factor] = [(np.mean(v), np.std(v)) for v in (fids, corrected, kids)]
    print(f"{len(phi)} real chips of {args.real}; {CHIPS} drawn {args.draws} times per factor")
    print("| spread × | φ-FID (÷ as they are) | its spread over draws | corrected (÷ as they are) | its spread "
          "| KID ×10³ | its spread |")
    print("|---|---|---|---|---|---|---|")
    (base, _), (base_corrected, _), _ = rows[1.0]
    for factor, ((f, fs), (c, cs), (k, ks)) in rows.items():
        print(f"| {factor:g} | {f:.1f} ({f / base:.2f}) | {fs:.1f} | {c:.1f} ({c / base_corrected:.2f}) | {cs:.1f} "
              f"| {k * 1e3:.1f} | {ks * 1e3:.1f} |")


if __name__ == "__main__":
    main()
