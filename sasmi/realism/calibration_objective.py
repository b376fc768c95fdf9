"""`sasmi calibrate`'s objective: the real chips' reference figures, and the score of a trial's renders.

    objective = mean over the checked statistics of min(d, 4)²  +  phi_weight x φ-FID ratio
                + distribution_weight x mean over the statistics of min(|AUC - 0.5| / tolerance, 4)²
                + variety_weight x max(0, 1 - recall / the real chips' own recall)

(sasmi/realism/calibrate.py says what each term holds; docs/calibrate.md, *What it minimises*.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sasmi.chips.compare import EVERY_CHIP_EXTRAS, TARGET_EXTRAS, TOLERANCES, Tolerance
from sasmi.chips.stats import MASK_STATISTICS, STATISTICS, chip_statistics, image_statistics
from sasmi.errors import SasmiError
from sasmi.eval.signature import chip_statistics as signature_statistics

FAR = 4.0  # tolerances: a statistic further off than this adds no more, so one cannot drown the rest
# the tolerances a calibration matches; the share of chips with a target found (`found_tolerance`) counts on every
# chip: a preset whose targets mostly vanish into the floor keeps the target medians of the few left, and on floor
# chips ripple crests and rocks read as targets
OBJECTIVE = {**TOLERANCES, **TARGET_EXTRAS, **EVERY_CHIP_EXTRAS}
# share of a set's half-split FID that its own spread adds to its FID to others: n chips add about c x spread / n,
# each half of n / 2 adds 2c x spread / n, so the two halves carry 4 times the set's share (BIAS_SHARE = 1 / 4)
BIAS_SHARE = 0.25
HALF_SPLITS = 4  # fixed random halvings averaged, so that the luck of one halving moves the score less


@dataclass(frozen=True)
class Weights:
    """What the objective adds to the statistics' term (sasmi/realism/calibrate.py says why each is there)."""
    phi: float = 1.0  # the φ-FID ratio
    distribution: float = 0.0  # the statistics' distributions, chip by chip (`distribution_distances`)
    variety: float = 0.0  # recall's shortfall
    spread_correction: bool = True  # φ-FID less the bias of the renders' own spread (False: the plain FID)


@dataclass(frozen=True)
class RealChips:
    folder: Path
    medians: dict[str, float]
    checked: tuple[str, ...]  # the statistics matched: the target ones only where most chips show a target
    tolerances: dict[str, Tolerance]  # statistic -> tolerance; targets_found's from `found_tolerance`
    phi: np.ndarray  # (N, D) float64
    phi_reference: float  # FID of `chips` real chips to the other real chips, averaged over draws
    phi_halves: float  # half-split FID of those `chips` real chips (`half_split_fid`), averaged over the same draws
    recall_reference: float  # share of the other real chips near `chips` real chips in φ, averaged over the same draws
    # each statistic of the distribution term of every chip, (N,), NaN where a chip lacks it: the checked ones (but
    # the share of chips with a target, a share of the whole set) and the nine of sasmi.eval.signature
    per_chip: dict[str, np.ndarray]
    images: np.ndarray  # (N, S, S) float32 in [0, 1]


def real_chips(folder: str | Path, encoder, chips: int, size: int, seed: int, draws: int = 16) -> RealChips:
    """The real chips at `size` px, their statistics' medians and φ, and their reference figures for trials of
    `chips` renders (`phi_references`)."""
    from sasmi.eval.features import image_paths, load_images, phi_features

    stats = chip_statistics(folder, size)
    images = load_images(image_paths(folder), size)
    if len(images) < chips + 8:
        raise SasmiError(f"--real {folder}: {len(images)} chips; calibrating with --chips {chips} needs at "
                         f"least {chips + 8}")
    phi = phi_features(encoder, images)
    targets = stats["targets_found"] >= 0.5  # seafloor chips: a target statistic is a false alarm's size
    checked = (*(k for k in OBJECTIVE if targets or k not in (*MASK_STATISTICS, *TARGET_EXTRAS)), "targets_found")
    values = {k: s["median"] for k, s in stats["summary"].items()} | {"targets_found": stats["targets_found"]}
    tolerances = {**OBJECTIVE, "targets_found": found_tolerance(values["targets_found"], len(images), chips)}
    per_chip = {k: stats["per_chip"][k] for k in checked if k != "targets_found"} | signature_statistics(images)
    return RealChips(Path(folder), values, checked, tolerances, phi, images=images, per_chip=per_chip,
                     **phi_references(phi, chips, seed, draws))


def found_tolerance(share: float, real: int, renders: int) -> Tolerance:
    """How far a trial's share of chips with a target found may lie from the real chips' `share`: two standard errors
    of the difference between the shares of `renders` and of `real` chips (binomial). The real share is counted with
    one chip more of each kind, so that floors on which none is found still allow for chance; rounded to 0.01. 83 % of
    the 115 MILCO train targets and 32 renders a trial give ± 0.15, 42 floors without one and 16 renders ± 0.09."""
    p = (share * real + 1) / (real + 2)
    return Tolerance("diff", 0.0, round(2 * math.sqrt(p * (1 - p) * (1 / renders + 1 / real)), 2))


def auc_tolerance(real: int, renders: int) -> float:
    """How far one statistic's ROC AUC, `renders` renders against `real` real chips, may lie from 0.5: two standard
    errors of the AUC of two samples of one distribution (Mann-Whitney's U). 32 renders and 115 chips: ± 0.12."""
    return 2 * math.sqrt((real + renders + 1) / (12 * real * renders))


def distribution_distances(ours: dict[str, np.ndarray], real: RealChips) -> dict[str, dict[str, float]]:
    """Per statistic of `real.per_chip` (`ours`: the renders' values, chip by chip), the ROC AUC by which it alone
    tells the renders from the real chips, over the chips where both show it, and how many tolerances that lies from
    0.5. A median within its tolerance still lets a classifier tell the chips apart where most renders' values lie
    above or below most real chips' (targets a little long in most chips, shadows covering a little more of each);
    the AUC counts every chip, as the two-sample test sees them."""
    from scipy.stats import mannwhitneyu

    out = {}
    for name, values in real.per_chip.items():
        a, b = ours[name][np.isfinite(ours[name])], values[np.isfinite(values)]
        if len(a) < 2 or len(b) < 2:  # a target statistic where (nearly) no render shows one: the share says so
            continue
        auc = float(mannwhitneyu(a, b).statistic / (len(a) * len(b)))  # P(render > real) + half the ties
        out[name] = {"auc": auc, "distance": abs(auc - 0.5) / auc_tolerance(len(b), len(a))}
    return out


def phi_references(phi: np.ndarray, chips: int, seed: int, draws: int = 16) -> dict:
    """RealChips' figures from the real chips' φ alone, what a trial's renders are measured against: FID, half-split
    FID and recall of `chips` real chips against the others, averaged over `draws` random draws (seeded by `seed`)."""
    from sasmi.eval.manifold import precision_recall
    from sasmi.eval.metrics import fid

    rng = np.random.default_rng([seed, 7])
    reference, halves, recall = [], [], []
    for _ in range(draws):
        order = rng.permutation(len(phi))
        drawn, rest = phi[order[:chips]], phi[order[chips:]]
        reference.append(fid(drawn, rest))
        halves.append(half_split_fid(drawn))
        recall.append(precision_recall(rest, drawn)[1])
    return {"phi_reference": float(np.mean(reference)), "phi_halves": float(np.mean(halves)),
            "recall_reference": float(np.mean(recall))}


def half_split_fid(features: np.ndarray) -> float:
    """FID between two halves of one set of chips, averaged over HALF_SPLITS fixed halvings: what sampling
    alone adds to the FID of half as many chips, which grows with the set's spread."""
    from sasmi.eval.metrics import fid

    rng = np.random.default_rng(0)  # fixed: the same renders score the same in every trial
    half = len(features) // 2
    orders = [rng.permutation(len(features)) for _ in range(HALF_SPLITS)]
    return float(np.mean([fid(features[o[:half]], features[o[half:2 * half]]) for o in orders]))


def spread_corrected_fid(features: np.ndarray, real_phi: np.ndarray, real_halves: float) -> float:
    """The FID of a trial's `features` to the real chips' φ, less BIAS_SHARE of the amount by which their half-split
    FID exceeds that of as many real chips (`real_halves`: RealChips.phi_halves, known at a trial's size only): the
    FID of a few renders in φ's 1024 dimensions falls as they grow alike, since less spread means less sampling
    noise in their covariance; corrected, renders drawn in towards their mean no longer score better than the same
    renders as they are (benchmarks/calibrate_phi_distance.py)."""
    from sasmi.eval.metrics import fid

    return fid(features, real_phi) - BIAS_SHARE * (half_split_fid(features) - real_halves)


def per_chip_statistics(images: np.ndarray) -> dict[str, np.ndarray]:
    """Every statistic of `sasmi stats` (NaN where a chip lacks it) and the nine of the signature, chip by chip."""
    rows = [image_statistics(im) for im in images]
    return {k: np.array([r[k] for r in rows]) for k in STATISTICS} | signature_statistics(images)


def medians(per_chip: dict[str, np.ndarray]) -> dict[str, float]:
    """Every statistic's median over the chips where it is found, and the share of chips with a target."""
    out = {k: float(np.median(v[np.isfinite(v)])) if np.isfinite(v).any() else math.nan
           for k, v in per_chip.items() if k in STATISTICS}
    out["targets_found"] = float(np.isfinite(per_chip["shadow_length"]).mean())
    return out


def score(images: np.ndarray, real: RealChips, encoder, weights: Weights = Weights()) -> dict:
    """The objective of a set of renders, with its parts: tolerance distances, passes, φ-FID ratio, the statistics'
    AUCs, recall."""
    from sasmi.eval.features import phi_features
    from sasmi.eval.manifold import precision_recall
    from sasmi.eval.metrics import fid

    per_chip = per_chip_statistics(images)
    ours = medians(per_chip)
    distances = {k: real.tolerances[k].distance(real.medians[k], ours[k]) for k in real.checked}
    features = phi_features(encoder, images)
    distance = (spread_corrected_fid(features, real.phi, real.phi_halves) if weights.spread_correction
                else fid(features, real.phi))
    ratio = distance / real.phi_reference
    stats_term = float(np.mean([min(d, FAR) ** 2 for d in distances.values()]))
    # the AUCs cost every trial time: computed where the term is weighted, or for the report (`final_score`)
    aucs = distribution_distances(per_chip, real) if weights.distribution else {}
    distribution_term = float(np.mean([min(s["distance"], FAR) ** 2 for s in aucs.values()])) if aucs else None
    recall = precision_recall(real.phi, features)[1]
    shortfall = max(0.0, 1.0 - recall / max(real.recall_reference, 1e-6))
    objective = (stats_term + weights.phi * ratio + (weights.distribution * distribution_term if aucs else 0.0)
                 + weights.variety * shortfall)
    return {"objective": objective, "statistics": stats_term, "distribution": distribution_term,
            "aucs": {k: s["auc"] for k, s in aucs.items()},
            "phi_ratio": ratio, "recall": recall, "distances": distances, "medians": ours, "features": features,
            "per_chip": per_chip,
            "passed": sum(distances[k] <= 1 for k in distances if k in TOLERANCES)}


def final_score(images: np.ndarray, real: RealChips, encoder, weights: Weights, seed: int) -> dict:
    """`score` with the φ-FID ratio, precision and recall of `sasmi evaluate` (matched sizes) and its two-sample test
    (`told_apart`): the report's figures."""
    from sasmi.eval.manifold import precision_recall_matched
    from sasmi.eval.metrics import fid_ratio_matched

    # the report renders more chips than a trial, and the real chips' half-split FID is known at a trial's size
    # only (it does not fall as 1 / n in φ's dimensions), so this objective is the plain one
    s = score(images, real, encoder, replace(weights, spread_correction=False))
    aucs = s["aucs"] or {k: d["auc"] for k, d in distribution_distances(s["per_chip"], real).items()}
    ratio = fid_ratio_matched(s["features"], real.phi, 200, seed)
    precision, recall = precision_recall_matched(real.phi, s["features"], seed=seed)
    told = told_apart(real.images, images, seed)
    return {**s, "aucs": aucs, "phi_ratio": ratio.value, "phi_ratio_std": ratio.std, "precision": precision.value,
            "recall": recall.value, "two_sample": told["auc"], "two_sample_std": told["auc_std"]}


def told_apart(real: np.ndarray, images: np.ndarray, seed: int) -> dict:
    """`sasmi evaluate`'s two-sample test of renders against the real chips, both (N, S, S) in [0, 1]: ROC AUC of a
    small CNN telling them apart (0.5: it cannot). Of calibrated presets, the one it tells less often from the chips
    calibrated to was told less often from held-out chips of the same sonar too (docs/calibrate.md)."""
    from sasmi.eval.config import TwoSampleConfig
    from sasmi.eval.features import to_pixels
    from sasmi.eval.two_sample import resized, two_sample_auc

    cfg = TwoSampleConfig()
    return two_sample_auc(resized(to_pixels(real), cfg.size), resized(to_pixels(images), cfg.size), cfg, seed)
