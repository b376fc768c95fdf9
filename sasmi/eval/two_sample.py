"""Classifier two-sample test (Lopez-Paz & Oquab 2017): can a small CNN tell a set from the real chips?

φ-FID compares distributions in φ's space and is nearly blind to what a plain classifier sees
(speckle, edges, gray-level texture). Here the small CNN of sasmi.eval.classifier learns real
(0) against generated (1) on all folds but one and scores the held-out fold by ROC AUC:
0.5 means it cannot tell them apart, 1.0 that it always can. K folds over R repeats give the
spread; a large set takes one repeat of which only some folds are held out, since their held-out
chips alone pin the AUC and each classifier is the evaluation's slowest part. Every generated chip
held out gets its probability of being generated; the chips it finds most synthetic are drawn
beside their nearest real chip in φ, so the signature can be seen.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from sasmi.eval import classifier
from sasmi.eval.config import TwoSampleConfig
from sasmi.eval.features import FeatureSet
from sasmi.eval.neighbours import nearest
from sasmi.eval.report import mosaic_figure
from sasmi.eval.signature import signature, signature_markdown

FIGURE = "most_synthetic.png"


def resized(images: np.ndarray, size: int, block: int = 1024) -> np.ndarray:
    """(N, S, S) uint8 → (N, size, size) float32 in [0, 1], area-averaged when shrinking; `block` chips at a
    time, so that no float copy of the whole set at S is made (1.3 GB for 20,000 chips at 128 px)."""
    out = np.empty((len(images), size, size), np.float32)
    for start in range(0, len(images), block):
        x = torch.from_numpy(images[start:start + block]).float()[:, None] / 255.0
        if x.shape[-1] != size:
            x = F.interpolate(x, size=(size, size), mode="area" if x.shape[-1] > size else "bilinear")
        out[start:start + len(x)] = x[:, 0].numpy()
    return out


def two_sample_auc(real: np.ndarray, fake: np.ndarray, cfg: TwoSampleConfig, seed: int = 0) -> dict:
    """ROC AUC of real (N, s, s) against fake (M, s, s), both in [0, 1]: mean and spread over held-out folds and
    repeats, and each fake chip's held-out probability of being generated (averaged over repeats; NaN for the
    chips of large sets' folds that are never held out)."""
    from sklearn.metrics import roc_auc_score

    folds = max(2, min(cfg.folds, len(real), len(fake)))
    steps = training_steps(len(real) + len(fake), folds, cfg)
    large = min(len(real), len(fake)) >= cfg.large_from
    repeats = 1 if large else cfg.repeats
    scored = min(folds, cfg.large_scored_folds) if large else folds
    aucs, p_fake = [], np.zeros(len(fake))
    with tqdm(total=repeats * scored, desc="two-sample classifiers", unit="fold", leave=False, disable=None) as bar:
        for repeat in range(repeats):
            rng = np.random.default_rng(seed * 1000 + repeat)
            fold_r, fold_f = rng.permutation(len(real)) % folds, rng.permutation(len(fake)) % folds
            for k in range(scored):
                model = classifier.train(fake[fold_f != k], real[fold_r != k], steps,
                                         seed=seed * 1000 + repeat * folds + k, batch=cfg.batch)
                pr, pf = classifier.predict(model, real[fold_r == k]), classifier.predict(model, fake[fold_f == k])
                aucs.append(float(roc_auc_score(np.r_[np.zeros(len(pr)), np.ones(len(pf))], np.r_[pr, pf])))
                p_fake[fold_f == k] += pf / repeats
                bar.update()
    p_fake[fold_f >= scored] = np.nan  # folds never held out: no honest probability
    return {"auc": float(np.mean(aucs)), "auc_std": float(np.std(aucs)), "folds": folds, "scored_folds": scored,
            "repeats": repeats, "steps": steps, "aucs": aucs, "p_fake": p_fake}


def training_steps(n: int, folds: int, cfg: TwoSampleConfig) -> int:
    """`epochs` passes over the training folds of n chips, within [20, max_steps] batches."""
    return int(min(cfg.max_steps, max(20, math.ceil(cfg.epochs * n * (folds - 1) / folds / cfg.batch))))


def two_sample_metrics(real: FeatureSet, sets: Sequence[FeatureSet], cfg: TwoSampleConfig, seed: int,
                       out_dir: Path) -> dict:
    """Per set: ROC AUC ± of the two-sample test, its most synthetic chips (one figure row per set) and the plain
    statistics that tell it apart (sasmi.eval.signature)."""
    real_small = resized(real.images, cfg.size)
    result, rows = {}, []
    for i, s in enumerate(sets):
        t = two_sample_auc(real_small, resized(s.images, cfg.size), cfg, seed + 1 + i)
        worst = np.argsort(-t["p_fake"], kind="stable")[:cfg.shown]
        idx, dist = nearest(s.phi[worst], real.phi, 1)  # (L, 1) each
        result[s.name] = {k: v for k, v in t.items() if k != "p_fake"} | {
            "most_synthetic": [{"chip": s.name_of(j), "p_generated": float(t["p_fake"][j]),
                                "nearest_real": real.name_of(g), "phi_distance": float(d)}
                               for j, g, d in zip(worst, idx[:, 0], dist[:, 0])],
            "signature": signature(real.images, s.images, seed)}
        rows.append([cell for j, g in zip(worst, idx[:, 0])
                     for cell in ((s.image(j), f"{s.name[:12]}\np {t['p_fake'][j]:.2f}"),
                                  (real.image(g), "nearest real"))])
    if rows:
        mosaic_figure(rows, out_dir / FIGURE, gaps_before=range(2, len(rows[0]), 2))
    return result


def two_sample_markdown(result: dict, cfg: TwoSampleConfig) -> str:
    lines = [f"A small CNN learns real against each set at {cfg.size} px ({cfg.epochs} passes, at most "
             f"{cfg.max_steps} batches) on all folds but one "
             "and scores the held-out fold: ROC AUC 0.5 means it cannot tell the set from the real chips, "
             "1.0 that it always can (mean ± spread over folds and repeats).", "",
             "| set | ROC AUC | folds held out × repeats |", "|---|---:|---|"]
    lines += [f"| {name} | {m['auc']:.3f} ± {m['auc_std']:.3f} | "
              f"{m['scored_folds']} of {m['folds']} × {m['repeats']} |" for name, m in result.items()]
    lines += ["", f"Each set's chips the classifier finds most synthetic (p: held-out probability of being "
                  f"generated), each beside its nearest real chip in φ: ![most synthetic]({FIGURE})", ""]
    return "\n".join(lines + [signature_markdown({name: m["signature"] for name, m in result.items()})])
