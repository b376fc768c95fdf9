"""What else a real train chip could give a render besides its gray levels: variants of the donor match.

`real_levels` gives each translated chip a random train chip's gray levels (ranks kept, the
shadow's darkness kept: `Generator.at_donor_levels`). After 20 steps the SAS GAN is nearly the
identity and its translations score close to the full runs' (docs/results.md), so the match
applied to the renders themselves stands in for a short run.
This writes that stand-in and variants of it, each an ordinary render set (images, masks,
labels) for `sasmi evaluate` and `sasmi stats`:

    levels          the donor match as shipped (donor_levels_after, donor_shadow = 0.4)
    two_band        log intensity split at a Gaussian of --sigma px: the smooth band takes the
                    donor's smooth-band levels (ranks kept), the speckle band the donor's spread
    two_band_levels two_band, then the donor's levels as in `levels`
    speckle_spread  the render's own smooth band, its speckle band scaled to the donor's spread,
                    then the donor's levels: real chips' speckle goes with their brightness
                    (docs/matching.md, *What the renders miss*), the plain match keeps the render's
    truncated       the donor's levels pulled towards the donors' mean levels by --psi (the
                    truncation trick: fewer unusual chips)

Each chip's donor is the one `sasmi translate` would draw (the code seeded by the file's place).

    .venv/bin/python benchmarks/donor_transfer.py RENDERS --donors TRAIN_TARGETS --out DIR \
        [--variants levels two_band ...] [--sigma 4] [--psi 0.75]

Use train chips as donors and score against held-out chips (docs/gan.md, *Speckle and truncation*).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
from scipy.ndimage import gaussian_filter

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gan.generator import donor_index, donor_quantiles, keep_shadows, remap  # noqa: E402
from gan.translate import carry_labels  # noqa: E402
from sasmi.images import list_images, read_gray, write_gray  # noqa: E402
from sasmi.preprocess import load_image  # noqa: E402

EPS = 1e-3  # intensity floor before the logarithm: a zero pixel stays finite
SHADOW = 0.4  # `real_levels`' donor_shadow
VARIANTS = ("levels", "two_band", "two_band_levels", "speckle_spread", "truncated")


def take_levels(x: torch.Tensor, levels: torch.Tensor) -> torch.Tensor:
    """x (B, 1, S, S) in [-1, 1], ranks kept, at `levels` (B, K)."""
    return remap(x, donor_quantiles(x), levels)


def bands(x: torch.Tensor, sigma: float) -> tuple[torch.Tensor, torch.Tensor]:
    """x (B, 1, S, S) in [-1, 1] → log intensity's smooth band (Gaussian of sigma px) and the rest."""
    log = ((x + 1) / 2 + EPS).log()
    smooth = torch.from_numpy(np.stack([gaussian_filter(c, sigma, mode="reflect")
                                        for c in log[:, 0].numpy()]))[:, None]
    return smooth, log - smooth


def from_log(log: torch.Tensor) -> torch.Tensor:
    return ((log.exp() - EPS) * 2 - 1).clamp(-1, 1)


def spread_ratio(speckle: torch.Tensor, donor_speckle: torch.Tensor) -> torch.Tensor:
    """(B, 1, 1, 1): the donor's speckle spread over the chip's."""
    return (donor_speckle.flatten(1).std(1) / speckle.flatten(1).std(1).clamp_min(1e-6)).view(-1, 1, 1, 1)


def variant(name: str, x: torch.Tensor, donors: torch.Tensor, pick: torch.Tensor, sigma: float,
            psi: float) -> torch.Tensor:
    """x (B, 1, S, S) renders in [-1, 1]; donors (D, 1, S, S); pick (B,) donor index → like x."""
    donor = donors[pick]
    if name == "levels":
        out = take_levels(x, donor_quantiles(donor))
    elif name in ("two_band", "two_band_levels"):
        (smooth, speckle), (d_smooth, d_speckle) = bands(x, sigma), bands(donor, sigma)
        out = from_log(take_levels(smooth, donor_quantiles(d_smooth)) + speckle * spread_ratio(speckle, d_speckle))
        if name == "two_band_levels":
            out = take_levels(out, donor_quantiles(donor))
    elif name == "speckle_spread":
        (smooth, speckle), (_, d_speckle) = bands(x, sigma), bands(donor, sigma)
        out = take_levels(from_log(smooth + speckle * spread_ratio(speckle, d_speckle)), donor_quantiles(donor))
    elif name == "truncated":
        every = donor_quantiles(donors)  # (D, K)
        mean = every.mean(0, keepdim=True)
        out = remap(x, donor_quantiles(x), mean + psi * (every[pick] - mean))
    else:
        raise ValueError(f"unknown variant {name!r} (one of {VARIANTS})")
    return keep_shadows(x, out, SHADOW)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("renders", type=Path, help="a render set (images/, masks/, labels.jsonl)")
    ap.add_argument("--donors", type=Path, required=True, help="real train target chips")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    ap.add_argument("--sigma", type=float, default=4.0, help="px; where the smooth band ends")
    ap.add_argument("--psi", type=float, default=0.75, help="truncated: 1 = the donor's levels, 0 = the mean")
    ap.add_argument("--size", type=int, default=128)
    args = ap.parse_args()

    paths = list_images(args.renders / "images")
    x = torch.from_numpy(np.stack([read_gray(p) for p in paths]))[:, None].float() * 2 - 1  # (N, 1, S, S) in [-1, 1]
    donors = torch.from_numpy(np.stack([load_image(p, args.size) for p in list_images(args.donors)]))[:, None] * 2 - 1
    # the code `sasmi translate` draws for the file at place i; its last entry picks the donor
    codes = torch.stack([torch.randn(1, generator=torch.Generator().manual_seed(i)) for i in range(len(paths))])
    pick = donor_index(codes[:, -1], len(donors))  # (N,)
    for name in args.variants:
        out = args.out / name
        for path, chip in zip(paths, variant(name, x, donors, pick, args.sigma, args.psi)[:, 0].numpy()):
            write_gray(out / "images" / path.relative_to(args.renders / "images").with_suffix(".png"), (chip + 1) / 2)
        carry_labels(args.renders, out)
        print(f"{name}: {len(paths)} chips -> {out}")


if __name__ == "__main__":
    main()
