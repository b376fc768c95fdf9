"""Evaluation in φ space: FID with error bars, KID, precision/recall, nearest neighbours, t-SNE.

φ is the 1024-d code of the GAN's autoencoder (`gan.autoencoder.load_encoder`). Every
metric is a pure numpy function of feature arrays (N, D) float64, so the numbers can be
had from Python (`phi_fid(real_dir, fake_dir, encoder)`, `fid(a, b)`, ...) or as a report
(`evaluate_folders(...)` + `write_report(...)`, what `sasmi evaluate` runs). Metric
definitions: docs/evaluate.md.

Torch, matplotlib and scikit-learn are imported inside the functions that use them, so
importing this module (and `sasmi --help`) stays fast.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.images import atomic_path, list_images, read_gray, write_text

REAL_VS_REAL = "real→real"


@dataclass(frozen=True)
class EvalConfig:
    bootstrap: int = 100  # FID resamples (and real splits) behind each ±; each costs one SVD of at most N×N
    kid_subsets: int = 100  # KID is averaged over this many random subsets; ± is their std
    kid_subset_size: int = 100  # images per KID subset, at most half the smaller set (Bińkowski et al. 2018)
    pr_k: int = 3  # k of the k-NN balls that make the precision/recall manifolds (Kynkäänniemi et al. 2019)
    copy_percentile: float = 5.0  # "closer to a real image than this percentile of real→real nearest distances"
    neighbours_shown: int = 6  # generated images (rows) in each nearest-neighbour grid
    neighbours_k: int = 4  # nearest real images shown per distance (pixel, φ)
    tsne_per_set: int = 400  # points per set in the t-SNE; caps its run time at a few seconds per set
    tsne_perplexity: float = 30.0  # lowered automatically for small sets (t-SNE needs perplexity < N / 3)
    thumbnails_per_set: int = 3  # images drawn on the t-SNE map per set
    batch: int = 32  # encoder batch
    seed: int = 0  # every random choice (bootstrap, splits, subsets, shown images) derives from it


@dataclass(frozen=True)
class Estimate:
    value: float
    std: float  # spread of the resampled estimates (bootstrap, splits or subsets; see docs/evaluate.md)


@dataclass(frozen=True)
class FeatureSet:
    name: str
    folder: Path
    images: np.ndarray  # (N, S, S) float32 in [0, 1], exactly what the encoder saw
    phi: np.ndarray  # (N, D) float64


@dataclass(frozen=True)
class Section:
    title: str
    body: str  # markdown; figures are referenced by file name, saved next to report.md


@dataclass(frozen=True)
class Report:
    metrics: dict  # JSON-ready; each part of the evaluation owns one top-level key
    sections: tuple[Section, ...]

    def __add__(self, other: "Report") -> "Report":
        return Report({**self.metrics, **other.metrics}, self.sections + other.sections)


# ---------------------------------------------------------------------------------------
# φ features
# ---------------------------------------------------------------------------------------

def fit_image(image01: np.ndarray, size: int) -> np.ndarray:
    """(H, W) → (size, size): the GAN's own preprocessing (short side to `size`, centre crop)."""
    from gan.data import resize_short_side

    x = resize_short_side(image01, size)[0].numpy()  # (h, w), min(h, w) == size
    top, left = (x.shape[0] - size) // 2, (x.shape[1] - size) // 2
    return x[top:top + size, left:left + size]


def load_images(paths: Sequence[str | os.PathLike], size: int) -> np.ndarray:
    """(N, size, size) float32 in [0, 1]; a file that cannot be read is a SasmiError naming it."""
    out = np.empty((len(paths), size, size), dtype=np.float32)
    for i, path in enumerate(tqdm(paths, desc="read", unit="img", leave=False, disable=None)):
        out[i] = fit_image(read_gray(path), size)
    return out


def phi_features(encoder, images: np.ndarray | Sequence[str | os.PathLike], batch: int = 32) -> np.ndarray:
    """φ of image files or of an (N, H, W) array in [0, 1] → (N, D) float64.

    Images are brought to `encoder.image_size` as in training. The encoder is put in eval
    mode so that φ of an image does not depend on the batch it is in.
    """
    import torch

    size = encoder.image_size
    if isinstance(images, np.ndarray):
        images = np.stack([fit_image(im, size) for im in images]) if images.shape[1:] != (size, size) else images
    else:
        images = load_images(images, size)
    if len(images) == 0:
        raise SasmiError("phi_features: no images")
    encoder.eval()
    device = next(encoder.parameters()).device
    feats = []
    with torch.no_grad():
        for start in tqdm(range(0, len(images), batch), desc="φ", unit="batch", leave=False, disable=None):
            x = torch.from_numpy(np.ascontiguousarray(images[start:start + batch], dtype=np.float32))
            x = (x[:, None] * 2.0 - 1.0).to(device)  # (B, 1, S, S) in [-1, 1]
            phi = encoder(x)  # (B, D)
            assert phi.ndim == 2 and phi.shape[0] == x.shape[0], phi.shape
            feats.append(phi.double().cpu().numpy())
    return np.concatenate(feats)  # (N, D)


def load_set(name: str, folder: str | os.PathLike, encoder, batch: int = 32) -> FeatureSet:
    paths = list_images(folder)
    if not paths:
        raise SasmiError(f"{folder}: no images (png, jpg, tif, tiff, npy) in it")
    images = load_images(paths, encoder.image_size)
    return FeatureSet(name, Path(folder), images, phi_features(encoder, images, batch))


# ---------------------------------------------------------------------------------------
# Metrics: pure functions of (N, D) feature arrays
# ---------------------------------------------------------------------------------------

def _as_features(feats: np.ndarray, minimum: int, what: str) -> np.ndarray:
    x = np.asarray(feats, dtype=np.float64)
    if x.ndim != 2 or len(x) < minimum:
        raise SasmiError(f"{what}: needs at least {minimum} feature vectors (N, D), got shape {x.shape}")
    return x


def _cov_factor(x: np.ndarray) -> np.ndarray:
    """(N, D) → F (r, D) with Fᵀ F = cov(x) (ddof 1) and r = min(N, D) rows.

    For N > D, the R of a QR decomposition of the centred data: an exact factor, where a
    symmetric eigen square root would add √(round-off) for every near-zero eigenvalue.
    """
    n, d = x.shape
    centred = (x - x.mean(axis=0)) / math.sqrt(n - 1)
    return centred if n <= d else np.linalg.qr(centred, mode="r")


def fid(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets, in float64.

    ‖μa − μb‖² + tr Σa + tr Σb − 2 tr (Σa^½ Σb Σa^½)^½. With Σa = Faᵀ Fa and Σb = Fbᵀ Fb,
    Σa^½ Σb Σa^½ has the nonzero eigenvalues of C Cᵀ, C = Fa Fbᵀ (r_a × r_b), so the last
    trace is the sum of C's singular values (the square roots of the eigenvalues of the
    symmetric C Cᵀ, computed stably by SVD). No complex parts, no D×D sqrtm, exact when
    N < D (rank-deficient covariances), and at most N×N work per call.
    """
    a = _as_features(feats_a, 2, "fid")
    b = _as_features(feats_b, 2, "fid")
    if a.shape[1] != b.shape[1]:
        raise SasmiError(f"fid: feature dimensions differ ({a.shape[1]} vs {b.shape[1]})")
    fa, fb = _cov_factor(a), _cov_factor(b)
    tr_sqrt = np.linalg.svd(fa @ fb.T, compute_uv=False).sum()
    value = np.sum((a.mean(0) - b.mean(0)) ** 2) + np.sum(fa**2) + np.sum(fb**2) - 2.0 * tr_sqrt
    return max(float(value), 0.0)  # a squared distance; only round-off makes it negative


def one_blas_thread():
    """Context: BLAS on one thread. The metrics are many small (≤ N×N) products; on a busy
    machine, OpenBLAS threads waiting for a core made them 50× slower (measured, 2 cores)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def fid_bootstrap(feats_a: np.ndarray, feats_b: np.ndarray, n: int = 100, seed: int = 0) -> Estimate:
    """FID of the full sets ± the std of FIDs of `n` bootstrap resamples (both sets resampled)."""
    a, b = np.asarray(feats_a, np.float64), np.asarray(feats_b, np.float64)
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        reps = [fid(a[rng.integers(0, len(a), len(a))], b[rng.integers(0, len(b), len(b))])
                for _ in tqdm(range(n), desc="FID bootstrap", leave=False, disable=None)]
    return Estimate(fid(a, b), float(np.std(reps, ddof=1)) if n > 1 else math.nan)


def fid_real_split(feats_real: np.ndarray, n: int = 100, seed: int = 0) -> Estimate:
    """Reference FID of real vs real: mean ± std over `n` random splits into two disjoint halves."""
    x = _as_features(feats_real, 4, "fid_real_split")
    rng = np.random.default_rng(seed)
    half = len(x) // 2
    reps = []
    with one_blas_thread():
        for _ in tqdm(range(n), desc="FID real halves", leave=False, disable=None):
            order = rng.permutation(len(x))
            reps.append(fid(x[order[:half]], x[order[half:2 * half]]))
    return Estimate(float(np.mean(reps)), float(np.std(reps, ddof=1)) if n > 1 else math.nan)


def fid_ratio_matched(feats_set: np.ndarray, feats_real: np.ndarray, n: int = 100, seed: int = 0) -> Estimate:
    """FID(set, real) / FID(real, real) at equal sample sizes, so FID's small-sample bias cancels.

    Each of `n` replicates splits the real set into random halves A and B, draws
    m = min(|A|, |set|) images from the set and from A, and computes FID(set_m, B) and
    FID(A_m, B). Value: mean of the first / mean of the second; ± the std of the
    per-replicate ratios.
    """
    x = _as_features(feats_set, 2, "fid_ratio_matched (set)")
    real = _as_features(feats_real, 4, "fid_ratio_matched (real)")
    rng = np.random.default_rng(seed)
    half = len(real) // 2
    m = min(half, len(x))
    num, den = [], []
    with one_blas_thread():
        for _ in tqdm(range(n), desc="FID ratio", leave=False, disable=None):
            order = rng.permutation(len(real))
            a, b = real[order[:m]], real[order[half:2 * half]]
            num.append(fid(x[rng.choice(len(x), m, replace=False)], b))
            den.append(fid(a, b))
    num, den = np.array(num), np.array(den)
    if np.mean(den) <= 0:
        return Estimate(math.nan, math.nan)
    ratios = num / np.where(den > 0, den, np.nan)
    return Estimate(float(np.mean(num) / np.mean(den)), float(np.nanstd(ratios, ddof=1)) if n > 1 else math.nan)


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
    a = _as_features(feats_a, 4, "kid")
    b = _as_features(feats_b, 4, "kid")
    m = min(subset_size, min(len(a), len(b)) // 2)
    rng = np.random.default_rng(seed)
    with one_blas_thread():
        reps = [mmd2_unbiased(a[rng.choice(len(a), m, replace=False)], b[rng.choice(len(b), m, replace=False)])
                for _ in range(subsets)]
    return Estimate(float(np.mean(reps)), float(np.std(reps, ddof=1)) if subsets > 1 else math.nan)


def kid_real_split(feats_real: np.ndarray, subsets: int = 100, subset_size: int = 100, seed: int = 0) -> Estimate:
    """KID of real vs real: each subset pairs two disjoint random draws from the real set."""
    x = _as_features(feats_real, 8, "kid_real_split")
    m = min(subset_size, len(x) // 4)  # as in kid(): at most half of each half
    rng = np.random.default_rng(seed)
    reps = []
    with one_blas_thread():
        for _ in range(subsets):
            order = rng.permutation(len(x))
            reps.append(mmd2_unbiased(x[order[:m]], x[order[m:2 * m]]))
    return Estimate(float(np.mean(reps)), float(np.std(reps, ddof=1)) if subsets > 1 else math.nan)


def pairwise_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Euclidean distances (Na, Nb) in float64."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    sq = (a**2).sum(1)[:, None] + (b**2).sum(1)[None, :] - 2.0 * a @ b.T
    return np.sqrt(np.clip(sq, 0.0, None))


def _kth_neighbour_radius(x: np.ndarray, k: int) -> np.ndarray:
    d = pairwise_distances(x, x)
    np.fill_diagonal(d, np.inf)  # a point is not its own neighbour
    return np.partition(d, k - 1, axis=1)[:, k - 1]


def precision_recall(feats_real: np.ndarray, feats_fake: np.ndarray, k: int = 3) -> tuple[float, float]:
    """Improved precision and recall (Kynkäänniemi et al. 2019) with k-NN ball manifolds.

    precision: fraction of fake samples inside some real sample's ball (radius = distance
    to its k-th nearest real neighbour); recall: the same with the roles swapped.
    """
    real = _as_features(feats_real, k + 1, "precision_recall (real)")
    fake = _as_features(feats_fake, k + 1, "precision_recall (generated)")
    d = pairwise_distances(fake, real)  # (F, R)
    precision = np.mean((d <= _kth_neighbour_radius(real, k)[None, :]).any(axis=1))
    recall = np.mean((d.T <= _kth_neighbour_radius(fake, k)[None, :]).any(axis=1))
    return float(precision), float(recall)


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


def rms(feats: np.ndarray) -> float:
    """Root mean square entry: divides φ so that xᵀx / D ≈ 1, the regime the KID kernel is made for."""
    return float(np.sqrt(np.mean(np.asarray(feats, np.float64) ** 2))) or 1.0


def phi_fid(real: str | os.PathLike, fake: str | os.PathLike, encoder, batch: int = 32) -> float:
    """One call: φ-FID between two image folders, `encoder` from gan.autoencoder.load_encoder."""
    return fid(load_set("real", real, encoder, batch).phi, load_set("fake", fake, encoder, batch).phi)


# ---------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------

def evaluate_folders(real: str | os.PathLike, sets: dict[str, Path], encoder, out_dir: str | os.PathLike,
                     cfg: EvalConfig = EvalConfig()) -> Report:
    """One call: φ of every folder, then `evaluate` and target preservation (sasmi.sweeps).

    Pose sweeps need a renderer and a generator and are added by the caller
    (`sweeps.pose_sweep_from_runs`); `write_report` writes the result.
    """
    from sasmi.sweeps import target_preservation

    real_set = load_set("real", real, encoder, cfg.batch)
    minimum = 2 * (cfg.pr_k + 1)  # two real halves, each with more than k neighbours
    if len(real_set.phi) < minimum:
        raise SasmiError(f"{real}: {len(real_set.phi)} real images; at least {minimum} are needed")
    features = []
    for name, folder in sets.items():
        features.append(load_set(name, folder, encoder, cfg.batch))
        if len(features[-1].phi) <= cfg.pr_k:
            raise SasmiError(f"{folder}: {len(features[-1].phi)} images; at least {cfg.pr_k + 1} are needed")
    return evaluate(real_set, features, out_dir, cfg) + target_preservation(sets, out_dir)


def evaluate(real: FeatureSet, sets: Sequence[FeatureSet], out_dir: str | os.PathLike,
             cfg: EvalConfig = EvalConfig()) -> Report:
    """Realism table, copying detector and t-SNE of `sets` against `real`; figures go to out_dir."""
    out_dir = Path(out_dir)
    dim = real.phi.shape[1]
    warnings = [f"{s.name}: {len(s.phi)} images, fewer than φ's {dim} dimensions: its covariance is "
                f"rank-deficient, so FID is biased up and noisy; trust KID and the ratio, not the raw FID"
                for s in (real, *sets) if len(s.phi) < dim]
    if len(real.phi) // 2 < dim <= len(real.phi):
        warnings.append(f"{REAL_VS_REAL}: each half has {len(real.phi) // 2} images, fewer than φ's {dim} "
                        f"dimensions (see above)")
    with one_blas_thread():
        realism = realism_table(real, sets, cfg)
        copying = copying_metrics(real, sets, cfg, out_dir)
        tsne_section = tsne_figure(real, sets, cfg, out_dir)
    metrics = {"config": asdict(cfg), "phi_dim": dim, "image_size": int(real.images.shape[-1]),
               "real": {"dir": str(real.folder), "n": len(real.phi)},
               "sets": {s.name: {"dir": str(s.folder), "n": len(s.phi)} for s in sets},
               "realism": realism, "copying": copying, "warnings": warnings}
    notes = "".join(f"\n\n> **Warning.** {w}" for w in warnings)
    return Report(metrics, (
        Section("Realism in φ space", _realism_markdown(realism, real) + notes),
        Section("Copying detector: nearest real images", _copying_markdown(copying, sets, cfg)),
        tsne_section,
    ))


def realism_table(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig) -> dict:
    """FID ± (bootstrap), its matched-size ratio to real→real, KID ± and precision/recall per set."""
    scale = rms(real.phi)  # one scalar for all sets: FID ratios and precision/recall do not change
    order = np.random.default_rng(cfg.seed).permutation(len(real.phi))
    half_a, half_b = real.phi[order[:len(order) // 2]], real.phi[order[len(order) // 2:]]
    reference = fid_real_split(real.phi, cfg.bootstrap, cfg.seed)
    k = kid_real_split(real.phi / scale, cfg.kid_subsets, cfg.kid_subset_size, cfg.seed)
    precision, recall = precision_recall(half_a, half_b, cfg.pr_k)
    rows = {REAL_VS_REAL: {"n": [len(half_a), len(half_b)], "fid": reference.value, "fid_std": reference.std,
                           "fid_ratio": 1.0, "fid_ratio_std": math.nan, "kid": k.value, "kid_std": k.std,
                           "precision": precision, "recall": recall}}
    for i, s in enumerate(tqdm(sets, desc="realism", unit="set", leave=False, disable=None)):
        seed = cfg.seed + 1 + i
        f = fid_bootstrap(s.phi, real.phi, cfg.bootstrap, seed)
        ratio = fid_ratio_matched(s.phi, real.phi, cfg.bootstrap, seed)
        k = kid(s.phi / scale, real.phi / scale, cfg.kid_subsets, cfg.kid_subset_size, seed)
        precision, recall = precision_recall(real.phi, s.phi, cfg.pr_k)
        rows[s.name] = {"n": len(s.phi), "fid": f.value, "fid_std": f.std, "fid_ratio": ratio.value,
                        "fid_ratio_std": ratio.std, "kid": k.value, "kid_std": k.std,
                        "precision": precision, "recall": recall}
    return rows


def _pm(value: float, std: float, fmt: str) -> str:
    """'value ± std', or just the value where no spread was measured."""
    return f"{value:{fmt}} ± {std:{fmt}}" if math.isfinite(std) else f"{value:{fmt}}"


def _realism_markdown(rows: dict, real: FeatureSet) -> str:
    lines = [f"Real set: `{real.folder}` ({len(real.phi)} images). φ: {real.phi.shape[1]} dimensions at "
             f"{real.images.shape[-1]}² px. Each row compares its set with the real set; {REAL_VS_REAL} compares "
             "two disjoint random halves of the real set, the floor any generator can reach at that sample size.",
             "",
             "| set | images | φ-FID | ÷ real→real | KID ×10³ | precision | recall |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in rows.items():
        n = " + ".join(map(str, r["n"])) if isinstance(r["n"], list) else str(r["n"])
        lines.append(f"| {name} | {n} | {_pm(r['fid'], r['fid_std'], '.3g')} | {_pm(r['fid_ratio'], r['fid_ratio_std'], '.2f')} | "
                     f"{_pm(r['kid'] * 1e3, r['kid_std'] * 1e3, '.3f')} | {r['precision']:.2f} | {r['recall']:.2f} |")
    lines += ["", "- **φ-FID**: the set against the whole real set, ± the std over bootstrap resamples; real→real "
              "is the mean ± std over random splits of the real set into halves.",
              "- **÷ real→real**: FID of the set against a random real half B divided by FID of the other half A "
              "against B, with the set and A drawn to the same size, so that FID's small-sample bias cancels "
              "(raw FIDs at different sample sizes are not comparable); mean over random splits ± the std of "
              "the per-split ratios. About 1 means as close to the real images as real images are to each other.",
              "- **KID**: unbiased MMD² with the cubic polynomial kernel on φ divided by the real set's rms entry, "
              "mean ± std over random subsets; ≈ 0 (it can be negative) when the set looks real, reliable for "
              "small sets.",
              "- **precision / recall**: share of the set inside the real k-NN manifold, and of the real set "
              "inside the set's (k = 3). Precision is realism, recall is diversity.",
              "",
              "Lower FID, ratio and KID and higher precision and recall are more realistic."]
    return "\n".join(lines)


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
        _neighbour_grid(s, real, shown, (pix_idx, pix_d / pixel_scale), (phi_idx, phi_d),
                        out_dir / f"neighbours_{s.name}.png")
    _distance_histograms(real_nn, generated_nn, out_dir / "nearest_distances.png")
    return metrics


def _copying_markdown(copying: dict, sets: Sequence[FeatureSet], cfg: EvalConfig) -> str:
    p = cfg.copy_percentile
    lines = ["For each generated image, the distance to its nearest real image, compared with the distance of "
             "each real image to its nearest *other* real image. Pixel distance is the rms gray-level difference "
             "(0–1) at the encoder's size. A generator that copies training images shows a median ratio well "
             f"below 1 and far more than {p:g} % of its images below the real→real {p:g}th percentile.", "",
             f"| set | pixel: median ratio | pixel: below p{p:g} | φ: median ratio | φ: below p{p:g} |",
             "|---|---:|---:|---:|---:|"]
    for s in sets:
        c = copying[s.name]
        lines.append(f"| {s.name} | {c['pixel']['median_ratio']:.2f} | {100 * c['pixel']['fraction_below']:.1f} % | "
                     f"{c['phi']['median_ratio']:.2f} | {100 * c['phi']['fraction_below']:.1f} % |")
    lines += ["", "![nearest distances](nearest_distances.png)", ""]
    for s in sets:
        lines += [f"**{s.name}**: first column a generated image, then its {cfg.neighbours_k} nearest real images "
                  f"in pixel ℓ2, then in φ (distance above each).", "",
                  f"![neighbours of {s.name}](neighbours_{s.name}.png)", ""]
    return "\n".join(lines)


def tsne_figure(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig, out_dir: Path) -> Section:
    """2-D t-SNE of φ (after PCA to ≤ 50 dimensions) for all sets, coloured by set, with thumbnails."""
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.offsetbox import AnnotationBbox, OffsetImage
    from sklearn.decomposition import PCA
    from sklearn.manifold import TSNE

    rng = np.random.default_rng(cfg.seed)
    groups = [(s, np.sort(rng.choice(len(s.phi), min(cfg.tsne_per_set, len(s.phi)), replace=False)))
              for s in (real, *sets)]
    x = np.concatenate([s.phi[idx] for s, idx in groups])  # (n, D)
    x = PCA(n_components=min(50, *x.shape), random_state=cfg.seed).fit_transform(x)
    perplexity = min(cfg.tsne_perplexity, max(2.0, (len(x) - 1) / 3.0))
    xy = TSNE(perplexity=perplexity, init="pca", random_state=cfg.seed).fit_transform(x)  # (n, 2)

    fig = Figure(figsize=(8, 7))
    ax = fig.add_subplot()
    start = 0
    for colour, (s, idx) in enumerate(groups):
        pts = xy[start:start + len(idx)]
        ax.scatter(pts[:, 0], pts[:, 1], s=8, alpha=0.6, color=f"C{colour}", label=f"{s.name} ({len(idx)})")
        for j in rng.choice(len(idx), min(cfg.thumbnails_per_set, len(idx)), replace=False):
            thumb = OffsetImage(s.images[idx[j]], cmap="gray", norm=Normalize(0, 1), zoom=32 / s.images.shape[-1])
            ax.add_artist(AnnotationBbox(thumb, pts[j], frameon=True, pad=0.1,
                                         bboxprops={"edgecolor": f"C{colour}", "linewidth": 1.5}))
        start += len(idx)
    ax.legend(loc="best", fontsize=8, markerscale=2)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(f"t-SNE of φ (perplexity {perplexity:.0f})")
    save_figure(fig, out_dir / "tsne.png")
    return Section("t-SNE of φ", "Each point is one image; sets that overlap look alike to the encoder. A few "
                   "images are drawn at their positions, framed in their set's colour.\n\n![t-SNE](tsne.png)")


def save_figure(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")


def _neighbour_grid(s: FeatureSet, real: FeatureSet, shown: np.ndarray, pixel: tuple, phi: tuple, path: Path) -> None:
    """Rows: a generated image, its k nearest real images in pixel ℓ2, then in φ."""
    rows = []
    for i in shown:
        cells = [(s.images[i], s.name)]
        cells += [(real.images[j], f"px {d:.3f}") for j, d in zip(pixel[0][i], pixel[1][i])]
        cells += [(real.images[j], f"φ {d:.3g}") for j, d in zip(phi[0][i], phi[1][i])]
        rows.append(cells)
    k = pixel[0].shape[1]
    mosaic_figure(rows, path, gaps_before=(1, 1 + k))


def mosaic_figure(rows: Sequence[Sequence[tuple[np.ndarray, str]]], path: Path, gaps_before: Sequence[int] = ()) -> None:
    """A grid of (image (S, S) in [0, 1], caption) cells drawn as one image: one imshow is
    ~10× faster to save than a subplot per cell. A wider gap goes before the listed columns."""
    from matplotlib.figure import Figure

    size = rows[0][0][0].shape[-1]
    zoom = max(1.0, 96 / size)  # display px per image px: small images are enlarged to stay legible
    pad, caption = max(2, size // 16), math.ceil(28 / zoom)  # caption rows fit two lines of 7 pt text
    x0 = [pad + j * (size + pad) + 2 * pad * sum(j >= g for g in gaps_before) for j in range(len(rows[0]))]
    row_step = caption + size + pad
    canvas = np.ones((len(rows) * row_step + pad, x0[-1] + size + pad), dtype=np.float32)  # white background
    for r, cells in enumerate(rows):
        top = r * row_step + caption
        for x, (image, _) in zip(x0, cells):
            canvas[top:top + size, x:x + size] = image
    fig = Figure(figsize=(canvas.shape[1] * zoom / 100, canvas.shape[0] * zoom / 100), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    for r, cells in enumerate(rows):
        for x, (_, text) in zip(x0, cells):
            ax.text(x + size / 2, r * row_step + caption - 1, text, ha="center", va="bottom", fontsize=7)
    ax.set_axis_off()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)


def _distance_histograms(real_nn: dict, generated_nn: dict, path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.5))
    for ax, space, label in zip(fig.subplots(1, 2), ("pixel", "phi"), ("rms pixel difference", "φ distance")):
        values = [real_nn[space], *(g[space] for g in generated_nn.values())]
        bins = np.linspace(0.0, max(v.max() for v in values) * 1.02 or 1.0, 40)
        ax.hist(real_nn[space], bins=bins, density=True, color="0.6", label=f"{REAL_VS_REAL} (leave one out)")
        for colour, (name, g) in enumerate(generated_nn.items(), start=1):
            ax.hist(g[space], bins=bins, density=True, histtype="step", linewidth=1.8, color=f"C{colour}",
                    label=f"{name}→real")
        ax.set_xlabel(f"nearest-neighbour {label}")
        ax.legend(fontsize=7)
    save_figure(fig, path)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None  # JSON has no NaN/inf
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, Path):
        return str(x)
    return x


def write_report(out_dir: str | os.PathLike, report: Report, title: str = "sasmi evaluation") -> Path:
    """report.md (sections in order) and metrics.json in out_dir; returns the report path."""
    out_dir = Path(out_dir)
    body = "\n\n".join(f"## {s.title}\n\n{s.body.strip()}" for s in report.sections)
    write_text(out_dir / "report.md", f"# {title}\n\nMetric definitions: docs/evaluate.md in the sasmi "
               f"repository.\n\n{body}\n")
    write_text(out_dir / "metrics.json", json.dumps(_jsonable(report.metrics), indent=2, ensure_ascii=False) + "\n")
    return out_dir / "report.md"
