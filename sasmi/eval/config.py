"""What `sasmi evaluate` computes and shows: one config for the whole evaluation.

Stored in metrics.json (`config`), so a report says how it was made.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class TwoSampleConfig:
    folds: int = 5  # each fold is held out once; the others train the classifier
    repeats: int = 2  # fold assignments drawn anew: the spread is over folds x repeats ...
    large_from: int = 250  # ... but from this many chips a side, one repeat, of which only ...
    large_scored_folds: int = 3  # ... so many folds are held out: each classifier still learns from (folds-1)/folds
    # of the chips (the AUC grows with them), and 3/5 of 250+ a side pin the mean AUC to ~0.03 (all 5/5: ~0.025)
    epochs: int = 20  # passes over the training folds: enough for the small CNN to find a signature ...
    max_steps: int = 300  # ... in at most this many batches (a large set needs fewer passes)
    batch: int = 32  # half real, half generated
    size: int = 64  # chips are shrunk to this: the classifier sees texture and shape, and trains in seconds
    shown: int = 6  # chips drawn per set: those the classifier finds most synthetic


@dataclass(frozen=True)
class EvalConfig:
    # the most real splits and precision/recall draws behind each figure (fewer once its mean is known to
    # 0.005: sasmi.eval.metrics.MC_ERROR); each costs one SVD of at most N×N. 500: a few hundred real chips
    # need them all (at 100 a ratio still moves with the seed several times as much)
    bootstrap: int = 500
    kid_subsets: int = 100  # KID is averaged over this many random subsets; ± is their std
    kid_subset_size: int = 100  # images per KID subset, at most half the smaller set (Bińkowski et al. 2018)
    pr_k: int = 3  # k of the k-NN balls that make the precision/recall manifolds (Kynkäänniemi et al. 2019)
    copy_percentile: float = 5.0  # "closer to a real image than this percentile of real→real nearest distances"
    neighbours_shown: int = 6  # generated images (rows) in each nearest-neighbour grid
    neighbours_k: int = 4  # nearest real images shown per distance (pixel, φ)
    coverage_draws: int = 100  # draws of the generated set behind each real chip's coverage (recall chip by chip)
    least_covered_shown: int = 6  # real chips shown per set: those its generated chips cover least
    tsne_per_set: int = 400  # points per set in the t-SNE; caps its run time at a few seconds per set
    tsne_perplexity: float = 30.0  # lowered automatically for small sets (t-SNE needs perplexity < N / 3)
    tsne_iterations: int = 500  # 250 of early exaggeration, then 250 that settle a map of 800 points (1000: twice
    # the time for the same map: on 800 digits, trustworthiness 0.993 either way, KL 0.518 against 0.502)
    thumbnails_per_set: int = 3  # images drawn on the t-SNE map per set
    batch: int = 32  # encoder batch
    two_sample: TwoSampleConfig | None = field(default_factory=TwoSampleConfig)  # None: skip the two-sample test
    seed: int = 0  # every random choice (bootstrap, splits, subsets, shown images) derives from it


@dataclass(frozen=True)
class PreservationConfig:
    margin: int = 8  # px searched around the labelled target and shadow: a shift of a few px is measured, not missed
    smooth: float = 1.5  # px, Gaussian blur before thresholding: speckle changes from pixel to pixel
    dark_fraction: float = 0.5  # "dark" = below this fraction of the median seafloor (mask 0) level
    bright_percentile: float = 99.0  # "bright" = above this percentile of the seafloor level
    examples: int = 6  # images drawn with their measurements per set


@dataclass(frozen=True)
class SweepConfig:
    steps: int = 7  # poses per sweep (grid columns)
    reach: float = 0.5  # the diagonal runs from −reach to +reach of the half chip in x and y
    seed: int = 0  # preset draw used as the base scene (its first target is swept)
    spp: int = 64  # samples per pixel of the sweep renders
    batch: int = 8  # generator batch
