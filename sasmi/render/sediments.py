"""Two sediments on one floor (sand beside mud): patches of two backscatter strengths with sharp, ragged boundaries.

A Gaussian field smoothed over the patch size, cut at the level the second sediment's share sets, draws where each
sediment lies. The field is drawn on a grid wider than the chip by four of its sigmas, so a patch larger than the
chip leaves many chips one sediment and crosses others with one boundary, as real chips cut from a survey are; a field
drawn periodic on the chip would put a boundary through every chip.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, special

RAGGED = 0.35  # weight of a field six times finer: a boundary ragged as real sediment edges are, not a smooth contour
COARSE = 3.0  # grid steps per sigma of the patch field: a large patch costs no more than a small one


def _smooth_field(rng: np.random.Generator, size: int, sigma: float) -> np.ndarray:
    """(size, size) Gaussian field of unit sd smoothed over `sigma` px, not periodic on the chip."""
    step = max(sigma / COARSE, 1.0)
    margin = 4 * sigma
    points = int(math.ceil((size + 2 * margin) / step)) + 2
    smoothed = ndimage.gaussian_filter(rng.standard_normal((points, points)), sigma / step, mode="nearest")
    smoothed /= max(smoothed.std(), 1e-12)  # unit sd over the wide grid: a chip's own sd varies, as its share does
    centres = (np.arange(size) + 0.5 + margin) / step
    rows, cols = np.meshgrid(centres, centres, indexing="ij")
    return ndimage.map_coordinates(smoothed, [rows, cols], order=1, mode="nearest")


def _second_sediment(rng: np.random.Generator, size: int, sigma: float, share: float) -> np.ndarray:
    """(size, size) bool: where the second sediment lies, in patches of a field smoothed over `sigma` px;
    `share` of the floor on average over chips, any share on one chip."""
    field = _smooth_field(rng, size, sigma) + RAGGED * _smooth_field(rng, size, sigma / 6)
    return field / math.hypot(1.0, RAGGED) > special.ndtri(1.0 - share)


def mosaic(rng: np.random.Generator, size: int, sigma: float, share: float, contrast: float) -> np.ndarray:
    """(size, size) texture of mean 1 over chips: 1 on the first sediment, `contrast` on the second, both over
    (1 - share) + share x contrast, so a mosaic moves no floor's average level, only how it is spread."""
    second = _second_sediment(rng, size, sigma, share)
    return np.where(second, contrast, 1.0) / ((1.0 - share) + share * contrast)
