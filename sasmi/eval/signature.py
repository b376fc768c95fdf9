"""Which plain statistics tell a set from the real chips: a two-sample test a sonar researcher can read.

The classifier two-sample test (sasmi.eval.two_sample) says how easily a set is told apart, not
by what. Here each chip is reduced to a few named statistics of its gray levels, speckle and
layout; each statistic's ROC AUC (real 0, set 1) says how well it alone tells the set apart (0.5:
not at all; under 0.5: the set's values run lower), and a logistic regression on all of them,
cross-validated, how well they do together. A statistic far from 0.5 names a signature to fix.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from sasmi.chips.floor_texture import unexplained_spread
from sasmi.eval.metrics import cores

FOLDS = 5
# name: what it measures. Range runs along x (columns), the track along y (rows)
STATISTICS = {
    "level": "median gray level",
    "contrast": "std / mean over the chip",
    "bright tail": "99.9th percentile / median: the brightest highlight pixels",
    "dark": "fraction of pixels under a quarter of the median: shadow",
    "grain along range": "correlation of neighbouring pixels along range",
    "grain along track": "correlation of neighbouring pixels along track",
    "contrast wander": "spread of the log contrast of 1/16-chip blocks that their level does not explain",
    "range profile": "log of the far quarter's mean over the near quarter's",
    "bands along track": "std / mean of the row means",
}


def _lag1(x: np.ndarray, axis: int) -> np.ndarray:
    """Each chip's correlation of neighbouring pixels along `axis` (1: rows, along track; 2: columns, along range)."""
    z = x - x.mean(axis=(1, 2), keepdims=True)
    pairs = z[:, 1:] * z[:, :-1] if axis == 1 else z[:, :, 1:] * z[:, :, :-1]
    return pairs.mean(axis=(1, 2)) / np.maximum((z * z).mean(axis=(1, 2)), 1e-12)


def _contrast_wander(x: np.ndarray) -> np.ndarray:
    n, s, _ = x.shape
    b = max(s // 16, 2)
    blocks = x[:, :s // b * b, :s // b * b].reshape(n, s // b, b, s // b, b)
    mean, std = blocks.mean(axis=(2, 4)).reshape(n, -1), blocks.std(axis=(2, 4)).reshape(n, -1)
    level, contrast = np.log(mean + 1e-3), np.log(std / (mean + 1e-3) + 1e-3)
    return unexplained_spread(level, contrast, np.ones(level.shape, bool))


def chip_statistics(images: np.ndarray, block: int = 128) -> dict[str, np.ndarray]:
    """{statistic: (N,)} of (N, S, S) chips (uint8, or floats in [0, 1], taken to 8 bits), `block` chips at a time:
    no float copy of a whole large set is made."""
    with ThreadPoolExecutor(cores()) as pool:  # numpy lets go of the GIL: every core
        parts = list(pool.map(_statistics, (images[i:i + block] for i in range(0, len(images), block))))
    return {name: np.concatenate([p[name] for p in parts]) if parts else np.zeros(0) for name in STATISTICS}


def _quantiles(pixels: np.ndarray, qs: tuple[float, ...]) -> np.ndarray:
    """(len(qs), N): each chip's gray levels (N, P) uint8 at quantiles qs, the least level whose share reaches q,
    from one histogram per chip (a sort of every chip's pixels costs several times more)."""
    n, p = pixels.shape
    rows = 256 * np.arange(n, dtype=np.int32)[:, None]
    counts = np.bincount((pixels + rows).ravel(), minlength=256 * n).reshape(n, 256)
    share = np.cumsum(counts, axis=1) / p
    return np.stack([np.argmax(share >= q, axis=1) for q in qs]) / 255.0


def _statistics(images: np.ndarray) -> dict[str, np.ndarray]:
    pixels = images if images.dtype == np.uint8 else (np.clip(images, 0, 1) * 255 + 0.5).astype(np.uint8)
    x = pixels.astype(np.float32) / 255.0
    flat = x.reshape(len(x), -1)
    median, top = _quantiles(pixels.reshape(len(x), -1).astype(np.int32), (0.5, 0.999))
    median = np.maximum(median, 1e-3)
    mean = np.maximum(flat.mean(axis=1), 1e-3)
    quarter = x.shape[-1] // 4
    far, near = x[:, :, -quarter:].mean(axis=(1, 2)), x[:, :, :quarter].mean(axis=(1, 2))
    return {
        "level": median,
        "contrast": flat.std(axis=1) / mean,
        "bright tail": top / median,
        "dark": (flat < 0.25 * median[:, None]).mean(axis=1),
        "grain along range": _lag1(x, 2),
        "grain along track": _lag1(x, 1),
        "contrast wander": _contrast_wander(x),
        "range profile": np.log((far + 1e-3) / (near + 1e-3)),
        "bands along track": x.mean(axis=2).std(axis=1) / mean,
    }


def signature(real: np.ndarray, fake: np.ndarray, seed: int = 0) -> dict:
    """Each statistic's medians and ROC AUC, most telling first, and the cross-validated AUC of all together."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.metrics import roc_auc_score
    from sklearn.model_selection import StratifiedKFold, cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    r, f = chip_statistics(real), chip_statistics(fake)
    y = np.r_[np.zeros(len(real)), np.ones(len(fake))]
    rows = [{"statistic": name, "real": float(np.median(r[name])), "set": float(np.median(f[name])),
             "auc": float(roc_auc_score(y, np.r_[r[name], f[name]]))} for name in STATISTICS]
    rows.sort(key=lambda row: -abs(row["auc"] - 0.5))
    folds = min(FOLDS, len(real), len(fake))
    together = None
    if folds >= 2:
        x = np.nan_to_num(np.stack([np.r_[r[name], f[name]] for name in STATISTICS], axis=1))
        model = make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000, class_weight="balanced"))
        p = cross_val_predict(model, x, y, cv=StratifiedKFold(folds, shuffle=True, random_state=seed),
                              method="predict_proba")[:, 1]
        together = float(roc_auc_score(y, p))
    return {"statistics": rows, "all_together": together}


def signature_markdown(result: dict[str, dict], shown: int = 4) -> str:
    """Per set, its `shown` most telling statistics and the AUC of all of them together."""
    lines = ["What tells each set apart, statistic by statistic (ROC AUC of that statistic alone: 0.5 tells "
             "nothing, under 0.5 the set's values run lower; `sasmi.eval.signature` says what each measures), and "
             "a logistic regression on all of them (cross-validated):", "",
             "| set | all together | most telling statistics: real median → set median (AUC) |", "|---|---:|---|"]
    for name, s in result.items():
        together = "–" if s["all_together"] is None else f"{s['all_together']:.3f}"
        telling = "; ".join(f"{row['statistic']} {row['real']:.3g} → {row['set']:.3g} ({row['auc']:.2f})"
                            for row in s["statistics"][:shown])
        lines.append(f"| {name} | {together} | {telling} |")
    return "\n".join(lines)
