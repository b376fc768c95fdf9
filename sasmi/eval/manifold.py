"""Improved precision and recall (Kynkäänniemi et al. 2019) and recall chip by chip: which φ vectors lie
on the other set's manifold of k-NN balls. Pure functions of feature arrays (N, D), as sasmi.eval.metrics."""
from __future__ import annotations

import math

import numpy as np

from sasmi.eval.metrics import Estimate, as_features, every_blas_thread, mean_known, one_blas_thread, replicates
from sasmi.eval.neighbours import distance_blocks, kth_neighbour_radius, within_any_ball

DENSE_BYTES = 256 * 2**20  # the real halves' replicates share one float32 N × N distance matrix up to this size


def precision_recall(feats_real: np.ndarray, feats_fake: np.ndarray, k: int = 3) -> tuple[float, float]:
    """Improved precision and recall (Kynkäänniemi et al. 2019) with k-NN ball manifolds.

    precision: fraction of fake samples inside some real sample's ball (radius = distance
    to its k-th nearest real neighbour); recall: the same with the roles swapped.
    """
    real = as_features(feats_real, k + 1, "precision_recall (real)")
    fake = as_features(feats_fake, k + 1, "precision_recall (generated)")
    # in blocks of rows (sasmi.eval.neighbours): memory stays bounded at any set size
    precision = np.mean(on_manifold(fake, real, k))
    recall = np.mean(on_manifold(real, fake, k))
    return float(precision), float(recall)


def precision_recall_matched(feats_real: np.ndarray, feats_fake: np.ndarray, k: int = 3, n: int = 100,
                             seed: int = 0) -> tuple[Estimate, Estimate]:
    """Precision and recall at equal set sizes: each of `n` replicates draws m = min(|real|, |fake|)
    of each set (without replacement). A ball's radius shrinks as its set grows, so recall of a
    few real chips against many generated ones reads far lower than against as few of them:
    recall would fall the more chips one generated. Equal sizes, as in Kynkäänniemi et al.
    (50k and 50k) and as in the real→real row, make it a property of the distributions;
    precision's mean is unchanged."""
    real = as_features(feats_real, k + 1, "precision_recall (real)")
    fake = as_features(feats_fake, k + 1, "precision_recall (generated)")
    m = min(len(real), len(fake))
    if len(real) == len(fake):
        n = 1  # nothing to draw: every replicate would be the same
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        reps = replicates(lambda rows: precision_recall(real[rows[0]], fake[rows[1]], k),
                          lambda i: (rng.choice(len(real), m, replace=False), rng.choice(len(fake), m, replace=False)),
                          n, mean_known, desc="precision/recall")
    return _precision_recall_estimates(reps)


def precision_recall_real_split(feats_real: np.ndarray, k: int = 3, n: int = 100,
                                seed: int = 0) -> tuple[Estimate, Estimate]:
    """Precision and recall of one random half of the real set against the other, over `n` splits:
    what a perfect generator reaches at the size that `precision_recall_matched` compares."""
    x = as_features(feats_real, 2 * (k + 1), "precision_recall_real_split")
    rng = np.random.default_rng(seed)
    half = len(x) // 2
    if len(x) ** 2 * 4 <= DENSE_BYTES:  # every split's distances are in one matrix: computed once, not per split
        d = np.empty((len(x), len(x)), np.float32)
        with every_blas_thread():
            for start, block in distance_blocks(x, x):
                d[start:start + len(block)] = block
        np.fill_diagonal(d, np.inf)
        def compute(order):
            return _precision_recall_within(d, order[:half], order[half:2 * half], k)
    else:
        def compute(order):
            return precision_recall(x[order[:half]], x[order[half:2 * half]], k)
    with one_blas_thread():
        reps = replicates(compute, lambda i: rng.permutation(len(x)), n, mean_known, desc="precision/recall real halves")
    return _precision_recall_estimates(reps)


def _precision_recall_within(d: np.ndarray, real: np.ndarray, fake: np.ndarray, k: int) -> tuple[float, float]:
    """`precision_recall` of rows `real` and `fake` of one set, from the distances d among its rows (diagonal ∞)."""
    def radius(rows):
        return np.partition(d[np.ix_(rows, rows)], k - 1, axis=1)[:, k - 1]

    across = d[np.ix_(fake, real)]  # symmetric: its transpose holds real to fake
    return (float(np.mean((across <= radius(real)[None, :]).any(1))),
            float(np.mean((across.T <= radius(fake)[None, :]).any(1))))


def _precision_recall_estimates(values: np.ndarray) -> tuple[Estimate, Estimate]:
    """(n, 2) (precision, recall) replicates → each one's mean ± std over them (NaN ± for one)."""
    spread = values.std(axis=0, ddof=1) if len(values) > 1 else np.full(2, math.nan)
    return tuple(Estimate(float(values[:, i].mean()), float(spread[i])) for i in range(2))


def real_coverage(feats_real: np.ndarray, feats_fake: np.ndarray, k: int = 3, n: int = 100,
                  seed: int = 0) -> np.ndarray:
    """(N_real,) in [0, 1]: recall chip by chip. For each real sample, the share of `n` draws of
    m = min(|real|, |fake|) generated samples whose k-NN balls hold it: the matched size of
    `precision_recall_matched`, whose recall this averages to over the real set. 0: no draw of the
    generated set has a sample near this real one."""
    real = as_features(feats_real, 1, "real_coverage (real)")
    fake = as_features(feats_fake, k + 1, "real_coverage (generated)")
    m = min(len(real), len(fake))
    if m == len(fake):
        n = 1  # every draw would be the whole generated set
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        hits = replicates(lambda rows: on_manifold(real, fake[rows], k),
                          lambda i: rng.choice(len(fake), m, replace=False), n, desc="coverage")  # (n, N_real)
    return hits.mean(axis=0)


def on_manifold(points: np.ndarray, reference: np.ndarray, k: int = 3) -> np.ndarray:
    """(N,) bool: each point inside some reference sample's ball (radius: its distance to its k-th
    nearest reference neighbour); the mean over generated points against real ones is precision."""
    return within_any_ball(points, reference, kth_neighbour_radius(reference, k))
