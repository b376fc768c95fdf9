"""Realism metrics: pure functions of φ feature arrays (N, D), numpy in float64.

FID with bootstrap and matched-size errors, KID (precision/recall: sasmi.eval.manifold). Nothing here
reads files, draws or knows about image sets. Definitions: docs/evaluate.md.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError


@dataclass(frozen=True)
class Estimate:
    value: float
    std: float  # spread of the resampled estimates (bootstrap, splits or subsets; see docs/evaluate.md)


def as_features(feats: np.ndarray, minimum: int, what: str) -> np.ndarray:
    x = np.asarray(feats, dtype=np.float64)
    if x.ndim != 2 or len(x) < minimum:
        raise SasmiError(f"{what}: needs at least {minimum} feature vectors (N, D), got shape {x.shape}")
    return x


class Moments(NamedTuple):
    mean: np.ndarray  # (D,)
    factor: np.ndarray  # (r, D), factorᵀ factor = the covariance
    invertible: bool  # factor is a D × D Cholesky factor: the covariance has no zero eigenvalue


def _cov_factor(x: np.ndarray, counts: np.ndarray | None = None) -> Moments:
    """(N, D) → the mean and a factor F (r, D) with Fᵀ F = cov(x) (ddof 1), r = min(N, D); with `counts`, of
    the set in which row i occurs counts[i] times (a bootstrap resample without its repeated rows: a third less work).

    N ≤ D: the centred rows themselves. N > D: the Cholesky factor of the D × D covariance (N D² work, a third
    of a QR's), or the R of a QR of the centred rows where the covariance is singular (a constant feature).
    """
    n = len(x) if counts is None else int(counts.sum())
    mean = x.mean(axis=0) if counts is None else counts @ x / n
    centred = x - mean
    if counts is not None:
        centred *= np.sqrt(counts)[:, None]  # row i's outer product counts[i] times
    centred /= math.sqrt(n - 1)  # in place: one (N, D) copy fewer at the peak
    if len(x) <= x.shape[1]:
        return Moments(mean, centred, False)
    try:
        return Moments(mean, np.linalg.cholesky(centred.T @ centred).T, True)
    except np.linalg.LinAlgError:
        return Moments(mean, np.linalg.qr(centred, mode="r"), False)


def fid(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets, in float64.

    ‖μa − μb‖² + tr Σa + tr Σb − 2 tr (Σa^½ Σb Σa^½)^½. With Σa = Faᵀ Fa and Σb = Fbᵀ Fb,
    Σa^½ Σb Σa^½ has the nonzero eigenvalues of C Cᵀ, C = Fa Fbᵀ (r_a × r_b), so the last
    trace is the sum of C's singular values. No complex parts, no D×D sqrtm, exact when
    N < D (rank-deficient covariances), and at most N×N work per call.
    """
    a = as_features(feats_a, 2, "fid")
    b = as_features(feats_b, 2, "fid")
    if a.shape[1] != b.shape[1]:
        raise SasmiError(f"fid: feature dimensions differ ({a.shape[1]} vs {b.shape[1]})")
    return _fid_of(_cov_factor(a), _cov_factor(b))


def _fid_of(a: Moments, b: Moments) -> float:
    """`fid` from each set's moments."""
    c = a.factor @ b.factor.T
    if a.invertible and b.invertible:  # C has no zero singular value: the symmetric eigenproblem of C Cᵀ, a
        tr_sqrt = np.sqrt(np.clip(np.linalg.eigvalsh(c @ c.T), 0.0, None)).sum()  # half an SVD's time
    else:  # a zero singular value of C would come out of C Cᵀ as √(round-off): an SVD
        tr_sqrt = np.linalg.svd(c, compute_uv=False).sum()
    value = np.sum((a.mean - b.mean) ** 2) + np.sum(a.factor**2) + np.sum(b.factor**2) - 2.0 * tr_sqrt
    return max(float(value), 0.0)  # a squared distance; only round-off makes it negative


def _resampled(x: np.ndarray, rows: np.ndarray) -> Moments:
    """`_cov_factor` of x[rows] (rows drawn with repeats), from each distinct row once and its count."""
    distinct, counts = np.unique(rows, return_counts=True)
    return _cov_factor(x[distinct], counts.astype(np.float64))


def fid_mean_part(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """‖μa − μb‖², the part of `fid` that a shift of every feature vector by one offset would
    remove: what the two sets differ in on average (gray level, texture), as against how
    they spread (which scenes occur, their variety), the rest."""
    a, b = as_features(feats_a, 1, "fid_mean_part"), as_features(feats_b, 1, "fid_mean_part")
    return float(np.sum((a.mean(0) - b.mean(0)) ** 2))


def one_blas_thread():
    """Context: BLAS on one thread. The metrics are many small (≤ N×N) products; on a busy
    machine, OpenBLAS threads waiting for a core make them many times slower."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def every_blas_thread():
    """Context: BLAS on every core, for one large product with nothing beside it (a 6000 × 6000 distance matrix)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=cores(), user_api="blas")


FID_RESAMPLES = 100  # at most: a std from 100 resamples is within about 7 % of the true spread
MC_ERROR = 0.005  # replicates stop once their mean is known to this (the figures' second decimal) ...
MIN_REPLICATES = 50  # ... and at least this many are in
BATCH = 10  # replicates computed between two checks of the stop rule: fixed, so that results do not depend on the cores


def cores() -> int:
    return len(os.sched_getaffinity(0))


def replicates(compute: Callable, draw: Callable[[int], object], n: int,
               known: Callable[[np.ndarray], bool] | None = None, desc: str = "") -> np.ndarray:
    """compute(draw(i)) for i < n, in order: draws in this thread (one random stream), computations on
    every core (LAPACK releases the GIL; each call is one BLAS thread). With `known`, stop once at least
    MIN_REPLICATES are in and known(replicates so far) holds."""
    if n == 1:  # nothing to run beside it: its products on every core
        with every_blas_thread():
            return np.asarray([compute(draw(0))], np.float64)
    out = []
    with ThreadPoolExecutor(cores()) as pool, tqdm(total=n, desc=desc, leave=False, disable=None) as bar:
        for start in range(0, n, BATCH):
            inputs = [draw(i) for i in range(start, min(start + BATCH, n))]
            out += pool.map(compute, inputs)
            bar.update(len(inputs))
            if known is not None and len(out) >= MIN_REPLICATES and known(np.asarray(out, np.float64)):
                break
    return np.asarray(out, np.float64)


def mean_known(values: np.ndarray, relative: bool = False) -> bool:
    """Whether the mean of each column of `values` (replicates in rows) has a standard error within
    MC_ERROR (relative: within MC_ERROR of the mean's size)."""
    se = values.std(axis=0, ddof=1) / math.sqrt(len(values))
    return bool(np.all(se <= MC_ERROR * (np.abs(values.mean(axis=0)) if relative else 1.0)))


def _estimate(values: np.ndarray) -> Estimate:
    return Estimate(float(np.mean(values)), float(np.std(values, ddof=1)) if len(values) > 1 else math.nan)


def fid_bootstrap(feats_a: np.ndarray, feats_b: np.ndarray, n: int = 100, seed: int = 0) -> Estimate:
    """FID of the full sets ± the std of FIDs of min(n, FID_RESAMPLES) bootstrap resamples (both sets)."""
    a, b = np.asarray(feats_a, np.float64), np.asarray(feats_b, np.float64)
    rng = np.random.default_rng(seed)
    n = min(n, FID_RESAMPLES)
    with one_blas_thread():
        reps = replicates(lambda rows: _fid_of(_resampled(a, rows[0]), _resampled(b, rows[1])),
                          lambda i: (rng.integers(0, len(a), len(a)), rng.integers(0, len(b), len(b))), n,
                          desc="FID bootstrap")
        value = fid(a, b)
    return Estimate(value, float(np.std(reps, ddof=1)) if n > 1 else math.nan)


class RealSplits:
    """Random halves A | B of the real set, drawn from `seed` alone, and FID(A_m, B) of split i at size m,
    each computed once: every set compared at size m meets the same splits and the same denominators."""

    def __init__(self, feats_real: np.ndarray, seed: int = 0):
        self.real = as_features(feats_real, 4, "real splits")
        self.half = len(self.real) // 2
        self.rng = np.random.default_rng([seed, 0])
        self.orders: list[np.ndarray] = []
        self.fids: dict[tuple[int, int], float] = {}

    def order(self, i: int) -> np.ndarray:
        """Split i's permutation (drawn in order, in the calling thread)."""
        while len(self.orders) <= i:
            self.orders.append(self.rng.permutation(len(self.real)).astype(np.int32))
        return self.orders[i]

    def a(self, i: int, m: int) -> np.ndarray:
        return self.real[self.order(i)[:m]]

    def b(self, i: int) -> np.ndarray:
        return self.real[self.order(i)[self.half:2 * self.half]]

    def fid(self, i: int, m: int) -> float:
        if (i, m) not in self.fids:
            self.fids[(i, m)] = fid(self.a(i, m), self.b(i))
        return self.fids[(i, m)]


def fid_real_split(feats_real: np.ndarray, n: int = 100, seed: int = 0, splits: RealSplits | None = None) -> Estimate:
    """Reference FID of real vs real: mean ± std over random splits into two disjoint halves, at most `n`,
    fewer once the mean is known to MC_ERROR of itself."""
    splits = splits or RealSplits(feats_real, seed)
    def draw(i: int) -> int:
        splits.order(i)
        return i

    with one_blas_thread():
        reps = replicates(lambda i: splits.fid(i, splits.half), draw, n, lambda v: mean_known(v, relative=True),
                          desc="FID real halves")
    return _estimate(reps)


def fid_ratio_matched(feats_set: np.ndarray, feats_real: np.ndarray, n: int = 100, seed: int = 0,
                      splits: RealSplits | None = None) -> Estimate:
    """FID(set, real) / FID(real, real) at equal sample sizes, so FID's small-sample bias cancels.

    Each replicate splits the real set into random halves A and B, draws m = min(|A|, |set|) images
    from the set and from A, and computes FID(set_m, B) and FID(A_m, B). Value: mean of the first /
    mean of the second; ± the std of the per-replicate ratios. At most `n` replicates, fewer once the
    ratio is known to MC_ERROR. Sets given one seed (or one `splits`) meet the same splits, so the
    ratio of their ratios is free of the splits' noise.
    """
    x = as_features(feats_set, 2, "fid_ratio_matched (set)")
    splits = splits or RealSplits(feats_real, seed)
    draw_rng = np.random.default_rng([seed, 1])
    m = min(splits.half, len(x))

    def draw(i: int):
        splits.order(i)
        return i, draw_rng.choice(len(x), m, replace=False)

    def compute(job) -> tuple[float, float]:
        i, rows = job
        return fid(x[rows], splits.b(i)), splits.fid(i, m)

    with one_blas_thread():
        reps = replicates(compute, draw, n, lambda v: mean_known(v[:, :1] / v[:, 1:]), desc="FID ratio")
    num, den = reps[:, 0], reps[:, 1]
    ratios = num / np.where(den > 0, den, np.nan)
    if np.mean(den) <= 0:
        return Estimate(math.nan, math.nan)
    return Estimate(float(np.mean(num) / np.mean(den)), float(np.nanstd(ratios, ddof=1)) if len(num) > 1 else math.nan)


def _poly_kernel(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return (x @ y.T / x.shape[1] + 1.0) ** 3


def mmd2_unbiased(x: np.ndarray, y: np.ndarray) -> float:
    """Unbiased MMD² with the cubic polynomial kernel k(x, y) = (xᵀy / D + 1)³; x, y (m, D)."""
    m = len(x)
    kxx, kyy, kxy = _poly_kernel(x, x), _poly_kernel(y, y), _poly_kernel(x, y)
    within = (kxx.sum() - np.trace(kxx) + kyy.sum() - np.trace(kyy)) / (m * (m - 1))
    return float(within - 2.0 * kxy.mean())


def kid(feats_a: np.ndarray, feats_b: np.ndarray, subsets: int = 100, subset_size: int = 100,
        seed: int = 0) -> Estimate:
    """Kernel inception distance: mean ± std of unbiased MMD² over random equal-size subsets.

    Unbiased, so two samples of one distribution give ≈ 0 (and may give < 0) at any size.
    Subsets hold at most half the smaller set, so that they differ and the ± means something.
    """
    a = as_features(feats_a, 4, "kid")
    b = as_features(feats_b, 4, "kid")
    m = min(subset_size, min(len(a), len(b)) // 2)
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        reps = [mmd2_unbiased(a[rng.choice(len(a), m, replace=False)], b[rng.choice(len(b), m, replace=False)])
                for _ in range(subsets)]
    return Estimate(float(np.mean(reps)), float(np.std(reps, ddof=1)) if subsets > 1 else math.nan)


def kid_real_split(feats_real: np.ndarray, subsets: int = 100, subset_size: int = 100, seed: int = 0) -> Estimate:
    """KID of real vs real: each subset pairs two disjoint random draws from the real set."""
    x = as_features(feats_real, 8, "kid_real_split")
    m = min(subset_size, len(x) // 4)  # as in kid(): at most half of each half
    rng = np.random.default_rng(seed)
    reps = []
    with one_blas_thread():
        for _ in range(subsets):
            order = rng.permutation(len(x))
            reps.append(mmd2_unbiased(x[order[:m]], x[order[m:2 * m]]))
    return Estimate(float(np.mean(reps)), float(np.std(reps, ddof=1)) if subsets > 1 else math.nan)


def rms(feats: np.ndarray) -> float:
    """Root mean square entry: divides φ so that xᵀx / D ≈ 1, the regime the KID kernel is made for."""
    return float(np.sqrt(np.mean(np.asarray(feats, np.float64) ** 2))) or 1.0
