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


BLOCK_BYTES = 64 * 2**20  # one block of distances, and of rows; bounds memory at any N (no N × N matrix)


def _rows(x: np.ndarray, step: int, dtype, centre: float):
    for start in range(0, len(x), step):
        rows = np.asarray(x[start:start + step], dtype)  # a view when x is of dtype already (φ): no copy
        yield start, rows - dtype(centre) if centre else rows


def distance_blocks(query: np.ndarray, reference: np.ndarray):
    """Yield (start, d): d (c, Nr), the Euclidean distances of query rows start … start + c
    to every reference row.

    φ (float64) is compared in float64. Any other rows (8-bit pixels) in float32, a block at a
    time about the middle gray, so that the squared norms stay small against float32's precision
    (a distance is off by at most about 1e-3 of its pixels' full scale, rms) and the products run at
    twice float64's speed. No (Nq, Nr) matrix is held: memory is about BLOCK_BYTES per array.
    """
    exact = query.dtype == np.float64 and reference.dtype == np.float64
    dtype, centre = (np.float64, 0.0) if exact else (np.float32, 127.5 if reference.dtype == np.uint8 else 0.0)
    item = np.dtype(dtype).itemsize
    n_ref, dim = reference.shape
    ref_step = n_ref if exact else max(1, BLOCK_BYTES // (item * dim))
    ref_sq = np.concatenate([(r**2).sum(1, dtype=np.float64) for _, r in _rows(reference, ref_step, dtype, centre)])
    for start, q in _rows(query, max(1, BLOCK_BYTES // (item * max(n_ref, dim))), dtype, centre):
        d = np.empty((len(q), n_ref), dtype)
        for r0, r in _rows(reference, ref_step, dtype, centre):
            np.matmul(q, r.T, out=d[:, r0:r0 + len(r)])
        d *= -2.0
        d += (q**2).sum(1, dtype=np.float64)[:, None].astype(dtype)
        d += ref_sq[None, :].astype(dtype)
        np.sqrt(np.clip(d, 0.0, None, out=d), out=d)
        yield start, d


def _without_self(d: np.ndarray, start: int) -> np.ndarray:
    """Leave one out: a block of x-to-x distances with each row's own point at infinity."""
    rows = np.arange(len(d))
    d[rows, start + rows] = np.inf
    return d


def kth_neighbour_radius(x: np.ndarray, k: int) -> np.ndarray:
    """(N,): distance of each row to its k-th nearest other row."""
    out = np.empty(len(x))
    for start, d in distance_blocks(x, x):
        out[start:start + len(d)] = np.partition(_without_self(d, start), k - 1, axis=1)[:, k - 1]
    return out


def within_any_ball(points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(Np,) bool: is each point within distance radii[j] of some centre j?"""
    out = np.empty(len(points), dtype=bool)
    for start, d in distance_blocks(points, centres):
        out[start:start + len(d)] = (d <= radii[None, :]).any(axis=1)
    return out


def nearest(query: np.ndarray, reference: np.ndarray, k: int, exclude_self: bool = False
            ) -> tuple[np.ndarray, np.ndarray]:
    """Indices and distances (M, k) of the k nearest reference rows to each query row, nearest first.

    `exclude_self` when query is reference (leave-one-out nearest neighbours).
    """
    k = min(k, len(reference) - int(exclude_self))
    idx, dist = np.empty((len(query), k), dtype=np.intp), np.empty((len(query), k))
    for start, d in distance_blocks(query, reference):
        if exclude_self:
            _without_self(d, start)
        part = np.argpartition(d, k - 1, axis=1)[:, :k] if k < d.shape[1] else np.tile(np.arange(k), (len(d), 1))
        part_d = np.take_along_axis(d, part, axis=1)
        order = np.argsort(part_d, axis=1, kind="stable")
        idx[start:start + len(d)] = np.take_along_axis(part, order, axis=1)
        dist[start:start + len(d)] = np.take_along_axis(part_d, order, axis=1)
    return idx, dist


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
    real_pixels = real.images.reshape(len(real.images), -1)  # uint8: converted block by block
    pixel_scale = 255.0 * math.sqrt(real_pixels.shape[1])  # ℓ2 / (255 √pixels) = rms difference in [0, 1]
    real_nn = {"pixel": nearest(real_pixels, real_pixels, 1, exclude_self=True)[1][:, 0] / pixel_scale,
               "phi": nearest(real.phi, real.phi, 1, exclude_self=True)[1][:, 0]}
    metrics, generated_nn = {}, {}
    rng = np.random.default_rng(cfg.seed)
    for s in tqdm(sets, desc="neighbours", unit="set", leave=False, disable=None):
        pixels = s.images.reshape(len(s.images), -1)
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
