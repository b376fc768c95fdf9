"""The evaluation as one call: φ of every folder, realism, coverage, copying, t-SNE and target
preservation, as a Report that `report.write_report` writes (what `sasmi evaluate` runs).

Pose sweeps need a renderer and a generator and are added by the caller
(`sweeps.pose_sweep_from_runs`).
"""
from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.eval import manifold, metrics
from sasmi.eval.config import EvalConfig
from sasmi.eval.coverage import FIGURE as COVERAGE_FIGURE, coverage_metrics
from sasmi.eval.features import FeatureSet, as_encoder, image_paths, load_set
from sasmi.eval.neighbours import copying_metrics
from sasmi.eval.preservation import target_preservation
from sasmi.eval.stages import FOLDER, Stages, stages_key
from sasmi.eval.two_sample import two_sample_markdown, two_sample_metrics
from sasmi.eval.report import REAL_VS_REAL, Report, Section, copying_markdown, coverage_markdown, realism_markdown, \
    statistics_markdown, tsne_figure
from sasmi.labels import has_labels

Log = Callable[[str], None]
Statistics = Callable[[Path], dict]  # a folder → {statistic name: number}, e.g. sasmi.chips.stats.median_statistics


def quiet(message: str) -> None:
    """The default log of the Python API: says nothing."""


class StderrLog:
    """One line per stage on stderr, with the seconds since the start: progress that
    survives without a terminal (tqdm bars only draw on one)."""

    def __init__(self, prefix: str = "sasmi evaluate"):
        self.prefix, self.start = prefix, time.perf_counter()

    def __call__(self, message: str) -> None:
        print(f"{self.prefix}: [{time.perf_counter() - self.start:6.1f} s] {message}", file=sys.stderr, flush=True)


def phi_fid(real: str | os.PathLike, fake: str | os.PathLike, phi=None, batch: int = 32, device="cpu") -> float:
    """One call: φ-FID between two image folders; `phi` an autoencoder run folder or weights file, an encoder
    (sasmi.gan.autoencoder.load_encoder), or None for the shipped φ (docs/models.md)."""
    encoder = as_encoder(phi, device)
    return metrics.fid(load_set("real", real, encoder, batch).phi, load_set("fake", fake, encoder, batch).phi)


def evaluate_folders(real: str | os.PathLike, sets: dict[str, Path], encoder, out_dir: str | os.PathLike,
                     cfg: EvalConfig = EvalConfig(), log: Log = quiet, cache_dir: str | os.PathLike | None = None,
                     statistics: Statistics | None = None, resumable: bool = False) -> Report:
    """φ of every folder, then `evaluate`, target preservation and (with `statistics`) the
    image-statistics table; figures go to out_dir.

    Folder sizes are checked before any φ is computed, so bad input fails at once. The real
    set's φ is cached in `cache_dir` (sasmi.eval.cache) when given: it is the set that stays
    the same from one evaluation to the next. Target preservation runs on every set with
    masks/ and labels.jsonl, the real set included when it has them. `resumable`: finished stages
    are kept in out_dir (sasmi.eval.stages) for a rerun of a stopped evaluation; the caller clears them.
    """
    minimum = 2 * (cfg.pr_k + 1)  # two real halves, each with more than k neighbours
    n_real = len(image_paths(real))
    if n_real < minimum:
        raise SasmiError(f"{real}: {n_real} real images; at least {minimum} are needed")
    for name, folder in sets.items():
        n = len(image_paths(folder))
        if n <= cfg.pr_k:
            raise SasmiError(f"{folder}: {n} images; at least {cfg.pr_k + 1} are needed")
    real_set = load_set("real", real, encoder, cfg.batch, cache_dir, log)
    kept = Path(out_dir) / FOLDER / "phi" if resumable else None
    features = [load_set(name, folder, encoder, cfg.batch, kept, log) for name, folder in sets.items()]
    stages = Stages(out_dir, stages_key(cfg, [real_set, *features])) if resumable else Stages(None)
    report = evaluate(real_set, features, out_dir, cfg, log, stages)
    report += _report(stages.get("preservation", lambda: _kept(target_preservation(
        {"real": Path(real), **sets} if has_labels(real) else sets, out_dir)), log, "target preservation"))
    if statistics is not None:
        report += _report(stages.get("statistics", lambda: _kept(image_statistics({"real": Path(real), **sets},
                                                                                   statistics)),
                                     log, "image statistics"))
    return report


def _kept(report: Report) -> dict:
    return {"metrics": report.metrics, "sections": [asdict(s) for s in report.sections]}


def _report(kept: dict) -> Report:
    return Report(kept["metrics"], tuple(Section(**s) for s in kept["sections"]))


def image_statistics(folders: dict[str, Path], statistics: Statistics) -> Report:
    """The per-set image-statistics table: `statistics(folder)` → {column: number} for each set.

    `sasmi evaluate` and `sasmi fit` pass `sasmi.chips.stats.median_statistics` as `statistics` to
    `evaluate_folders`, which calls this; the evaluation itself imports nothing of sasmi.chips.stats.
    """
    rows = {name: statistics(Path(folder)) for name, folder in folders.items()}
    return Report({"image_statistics": rows}, (Section("Image statistics", statistics_markdown(rows)),))


def evaluate(real: FeatureSet, sets: Sequence[FeatureSet], out_dir: str | os.PathLike,
             cfg: EvalConfig = EvalConfig(), log: Log = quiet, stages: Stages = Stages(None)) -> Report:
    """Realism table, coverage, copying detector and t-SNE of `sets` against `real`; figures go to out_dir,
    each stage's result to `stages` (kept there by a stopped run: not computed again)."""
    out_dir = Path(out_dir)
    dim = real.phi.shape[1]
    warnings = [f"{s.name}: {len(s.phi)} images, fewer than φ's {dim} dimensions: its covariance is "
                f"rank-deficient, so FID is biased up and noisy; trust KID and the ratio, not the raw FID"
                for s in (real, *sets) if len(s.phi) < dim]
    if len(real.phi) // 2 < dim <= len(real.phi):
        warnings.append(f"{REAL_VS_REAL}: each half has {len(real.phi) // 2} images, fewer than φ's {dim} "
                        f"dimensions (see above)")
    with metrics.one_blas_thread():
        realism = stages.get("realism", lambda: realism_table(real, sets, cfg), log, "realism: FID, its ratio, KID, "
                             f"precision/recall of {len(sets)} sets (at most {cfg.bootstrap} replicates each)")
        coverage = stages.get("coverage", lambda: coverage_metrics(real, sets, cfg, out_dir), log,
                              "coverage: the real chips each set covers least")
    # pixel distances are a few large products (N × N × pixels): BLAS on every core
    copying = stages.get("copying", lambda: copying_metrics(real, sets, cfg, out_dir), log,
                         "copying detector: nearest neighbours")
    tsne_section = Section(**stages.get("tsne", lambda: asdict(tsne_figure(*tsne_map(real, sets, cfg),
                                                                             out_dir / "tsne.png")), log, "t-SNE"))
    two_sample = {}
    if cfg.two_sample is not None:  # torch's own threads: outside the one-BLAS-thread block
        two_sample = stages.get("two_sample", lambda: two_sample_metrics(real, sets, cfg.two_sample, cfg.seed, out_dir),
                                log, f"two-sample test: a classifier against the real chips, {cfg.two_sample.folds} "
                                     "folds per set")
    result = {"config": asdict(cfg), "phi_dim": dim, "image_size": int(real.images.shape[-1]),
              "real": {"dir": str(real.folder), "n": len(real.phi)},
              "sets": {s.name: {"dir": str(s.folder), "n": len(s.phi)} for s in sets},
              "realism": realism, "two_sample": two_sample, "coverage": coverage, "copying": copying,
              "warnings": warnings}
    notes = "".join(f"\n\n> **Warning.** {w}" for w in warnings)
    return Report(result, (
        Section("Realism in φ space", realism_markdown(realism, real) + notes),
        *([Section("Two-sample test: can a classifier tell each set from the real chips?",
                   two_sample_markdown(two_sample, cfg.two_sample))] if two_sample else []),
        Section("Coverage: the real chips each set misses", coverage_markdown(coverage, COVERAGE_FIGURE)),
        Section("Copying detector: nearest real images", copying_markdown(copying, sets, cfg)),
        tsne_section,
    ))


def realism_table(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig) -> dict:
    """FID ± (bootstrap), its matched-size ratio to real→real, the part of FID from the means, KID ±,
    precision/recall and the distance of the chips' gray-level distributions (no φ) per set."""
    scale = metrics.rms(real.phi)  # one scalar for all sets: FID ratios and precision/recall do not change
    order = np.random.default_rng(cfg.seed).permutation(len(real.phi))
    half = len(order) // 2
    half_a, half_b = real.phi[order[:half]], real.phi[order[half:]]
    splits = metrics.RealSplits(real.phi, cfg.seed)  # the ratio's denominators: computed once for every set
    reference = metrics.fid_real_split(real.phi, cfg.bootstrap, splits=splits)
    k = metrics.kid_real_split(real.phi / scale, cfg.kid_subsets, cfg.kid_subset_size, cfg.seed)
    precision, recall = manifold.precision_recall_real_split(real.phi, cfg.pr_k, cfg.bootstrap, cfg.seed)
    real_levels = gray_levels(real.images)
    rows = {REAL_VS_REAL: {"n": [len(half_a), len(half_b)], "fid": reference.value, "fid_std": reference.std,
                           "fid_ratio": 1.0, "fid_ratio_std": math.nan,
                           "fid_mean_part": metrics.fid_mean_part(half_a, half_b), "kid": k.value, "kid_std": k.std,
                           "precision": precision.value, "precision_std": precision.std,
                           "recall": recall.value, "recall_std": recall.std,
                           "gray_levels": level_distance(real_levels[order[:half]], real_levels[order[half:]])}}
    for i, s in enumerate(tqdm(sets, desc="realism", unit="set", leave=False, disable=None)):
        seed = cfg.seed + 1 + i
        f = metrics.fid_bootstrap(s.phi, real.phi, cfg.bootstrap, seed)
        ratio = metrics.fid_ratio_matched(s.phi, real.phi, cfg.bootstrap, cfg.seed, splits)  # the same splits
        k = metrics.kid(s.phi / scale, real.phi / scale, cfg.kid_subsets, cfg.kid_subset_size, seed)
        precision, recall = manifold.precision_recall_matched(real.phi, s.phi, cfg.pr_k, cfg.bootstrap, seed)
        rows[s.name] = {"n": len(s.phi), "fid": f.value, "fid_std": f.std, "fid_ratio": ratio.value,
                        "fid_ratio_std": ratio.std, "fid_mean_part": metrics.fid_mean_part(s.phi, real.phi),
                        "kid": k.value, "kid_std": k.std,
                        "precision": precision.value, "precision_std": precision.std,
                        "recall": recall.value, "recall_std": recall.std,
                        "gray_levels": level_distance(gray_levels(s.images), real_levels)}
    return rows


def gray_levels(images: np.ndarray, block: int = 256):
    """(N, S, S) uint8 → (N, 27) torch: each chip's gray-level quantiles, as the SAS GAN's gray-level term
    (sasmi.gan.losses.gray_levels) sees them, with its linear interpolation between order statistics; 8-bit
    pixels sort by radix in a tenth of the float sort's time, in blocks of `block` chips."""
    import torch

    from sasmi.gan.losses import LEVEL_QUANTILES, LEVEL_TAIL
    from sasmi.preprocess import unit_to_signed

    pixels = images.reshape(len(images), -1)
    position = torch.cat([LEVEL_QUANTILES, LEVEL_TAIL]).double().numpy() * (pixels.shape[1] - 1)
    below = np.floor(position).astype(np.intp)
    above, weight = np.minimum(below + 1, pixels.shape[1] - 1), position - below
    levels = np.empty((len(images), len(position)))
    for i in range(0, len(images), block):
        ordered = np.sort(pixels[i:i + block], axis=1, kind="stable").astype(np.float64)  # stable: radix for uint8
        levels[i:i + block] = ordered[:, below] + weight * (ordered[:, above] - ordered[:, below])
    return unit_to_signed(torch.from_numpy(levels / 255.0).float())


def level_distance(a, b, block: int = 1024) -> float:
    """Energy distance between two sets of per-chip gray-level quantiles (≈ 0: alike): the definition of the
    SAS GAN's gray-level term (sasmi.gan.losses.energy_distance), in float64 and through matrix products, so
    that 6000 chips a set take a second where the loss's pairwise differences take ten."""
    import torch

    a, b = a.double(), b.double()

    def mean_distance(x, y, distinct: bool) -> float:
        total = 0.0
        for i in range(0, len(x), block):  # (block, len(y)) distances at a time
            d = torch.cdist(x[i:i + block], y, compute_mode="use_mm_for_euclid_dist")
            if distinct:  # each chip's distance to itself is no pair
                d[torch.arange(len(d)), torch.arange(i, i + len(d))] = 0.0
            total += float(d.sum())
        return total / (len(x) * (len(x) - 1) if distinct else len(x) * len(y))

    return 2 * mean_distance(a, b, False) - mean_distance(a, a, True) - mean_distance(b, b, True)


def tsne_map(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig
             ) -> tuple[list[tuple[FeatureSet, np.ndarray, np.ndarray]], np.ndarray, float]:
    """2-D t-SNE of φ (after PCA to ≤ 50 dimensions) of at most `tsne_per_set` images per set.

    Returns the groups (set, indices of its points, positions among them shown as
    thumbnails), the points (n, 2) of all groups in order, and the perplexity used.
    """
    from sklearn.decomposition import PCA
    from sklearn.manifold import TSNE

    rng = np.random.default_rng(cfg.seed)
    chosen = [(s, np.sort(rng.choice(len(s.phi), min(cfg.tsne_per_set, len(s.phi)), replace=False)))
              for s in (real, *sets)]
    x = np.concatenate([s.phi[idx] for s, idx in chosen])  # (n, D)
    x = PCA(n_components=min(50, *x.shape), random_state=cfg.seed).fit_transform(x)
    perplexity = min(cfg.tsne_perplexity, max(2.0, (len(x) - 1) / 3.0))
    xy = TSNE(perplexity=perplexity, init="pca", max_iter=cfg.tsne_iterations,
              random_state=cfg.seed).fit_transform(x)  # (n, 2)
    groups = [(s, idx, rng.choice(len(idx), min(cfg.thumbnails_per_set, len(idx)), replace=False))
              for s, idx in chosen]
    return groups, xy, perplexity
