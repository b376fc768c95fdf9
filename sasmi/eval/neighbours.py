"""Nearest neighbours in φ and pixel space, and the copying detector built on them.

A generator that copies its training images puts its outputs much closer to some real
image than real images are to each other; `copy_statistics` measures that.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from sasmi.eval.config import EvalConfig
from sasmi.eval.features import FeatureSet
from sasmi.eval.report import distance_histograms, neighbour_grid


def pairwise_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distances (Na, Nb) in float64."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    sq = (a**2).sum(1)[:, None] + (b**2).sum(1)[None, :] - 2.0 * a @ b.T
    return np.sqrt(np.clip(sq, 0.0, None))


def kth_neighbour_radius(x: np.ndarray, k: int) -> np.ndarray:
    d = pairwise_distances(x, x)
    np.fill_diagonal(d, np.inf)  # a point is not its own neighbour
    return np.partition(d, k - 1, axis=1)[:, k - 1]


def nearest(query: np.ndarray, reference: np.ndarray, k: int, exclude_self: bool = False
            ) -> tuple[np.ndarray, np.ndarray]:
    """Indices and distances (M, k) of the k nearest reference rows to each query row.

    `exclude_self` when query is reference (leave-one-out nearest neighbours).
    """
    d = pairwise_distances(query, reference)
    if exclude_self:
        np.fill_diagonal(d, np.inf)
    k = min(k, d.shape[1] - int(exclude_self))
    idx = np.argsort(d, axis=1)[:, :k]
    return idx, np.take_along_axis(d, idx, axis=1)


def copy_statistics(nn_generated: np.ndarray, nn_real: np.ndarray, percentile: float = 5.0) -> dict:
    """Compare generated→real nearest distances with real→real (leave-one-out) ones.

    A generator that copies its training images puts generated images much closer to a
    real image than real images are to each other: median_ratio ≪ 1 and
    fraction_below ≫ percentile / 100.
    """
    threshold = float(np.percentile(nn_real, percentile))
    return {"median": float(np.median(nn_generated)), "median_real": float(np.median(nn_real)),
            "median_ratio": float(np.median(nn_generated) / np.median(nn_real)),
            "threshold": threshold, "fraction_below": float(np.mean(nn_generated < threshold))}


def copying_metrics(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig, out_dir: Path) -> dict:
    """Nearest real neighbours of generated images in pixel ℓ2 (rms per pixel) and in φ; grids and histograms."""
    real_pixels = real.images.reshape(len(real.images), -1).astype(np.float64)
    pixel_scale = math.sqrt(real_pixels.shape[1])  # ℓ2 / √pixels = rms gray-level difference
    real_nn = {"pixel": nearest(real_pixels, real_pixels, 1, exclude_self=True)[1][:, 0] / pixel_scale,
               "phi": nearest(real.phi, real.phi, 1, exclude_self=True)[1][:, 0]}
    metrics, generated_nn = {}, {}
    rng = np.random.default_rng(cfg.seed)
    for s in tqdm(sets, desc="neighbours", unit="set", leave=False, disable=None):
        pixels = s.images.reshape(len(s.images), -1).astype(np.float64)
        pix_idx, pix_d = nearest(pixels, real_pixels, cfg.neighbours_k)
        phi_idx, phi_d = nearest(s.phi, real.phi, cfg.neighbours_k)
        generated_nn[s.name] = {"pixel": pix_d[:, 0] / pixel_scale, "phi": phi_d[:, 0]}
        metrics[s.name] = {space: copy_statistics(generated_nn[s.name][space], real_nn[space], cfg.copy_percentile)
                           for space in ("pixel", "phi")}
        shown = np.sort(rng.choice(len(s.images), min(cfg.neighbours_shown, len(s.images)), replace=False))
        neighbour_grid(s, real, shown, (pix_idx, pix_d / pixel_scale), (phi_idx, phi_d),
                        out_dir / f"neighbours_{s.name}.png")
    distance_histograms(real_nn, generated_nn, out_dir / "nearest_distances.png")
    return metrics
