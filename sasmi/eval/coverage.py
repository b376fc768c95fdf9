"""Which real chips a generated set leaves uncovered: recall, chip by chip.

Recall says how much of the real set the generated chips cover; this says which real chips they
miss. Each of the least covered is drawn beside the generated chip nearest it in φ, so that one
sees what the set offers in its place (for instance shadows half the chip long, or big, bright,
irregular highlights that a preset does not make).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from sasmi.eval import manifold
from sasmi.eval.config import EvalConfig
from sasmi.eval.features import FeatureSet
from sasmi.eval.neighbours import nearest
from sasmi.eval.report import mosaic_figure

FIGURE = "least_covered.png"


def _short(name: str, width: int = 18) -> str:
    """A caption that fits under a chip: the end of the stem, where chip names differ."""
    stem = Path(name).stem
    return stem if len(stem) <= width else "…" + stem[-(width - 1):]


def coverage_metrics(real: FeatureSet, sets: Sequence[FeatureSet], cfg: EvalConfig, out_dir: Path) -> dict:
    """Per set: the mean coverage (its recall), how many real chips no draw covers, and the least
    covered chips with their nearest generated chip; one figure row per set."""
    draws = min(cfg.coverage_draws, cfg.bootstrap)  # a quick evaluation (--bootstrap 10) stays quick
    result, rows = {}, []
    for i, s in enumerate(sets):
        cover = manifold.real_coverage(real.phi, s.phi, cfg.pr_k, draws, cfg.seed + 1 + i)  # (N_real,)
        least = np.argsort(cover, kind="stable")[:cfg.least_covered_shown]
        idx, dist = nearest(real.phi[least], s.phi, 1)  # (L, 1) each
        result[s.name] = {"mean": float(cover.mean()), "never": int(np.sum(cover == 0)),
                          "least": [{"chip": real.name_of(j), "covered": float(cover[j]),
                                     "nearest": s.name_of(g), "phi_distance": float(d)}
                                    for j, g, d in zip(least, idx[:, 0], dist[:, 0])]}
        rows.append([cell for j, g, d in zip(least, idx[:, 0], dist[:, 0])
                     for cell in ((real.image(j), f"{_short(real.name_of(j))}\ncovered {cover[j]:.2f}"),
                                  (s.image(g), f"nearest of {s.name[:10]}\nφ {d:.1f}"))])
    if rows:
        mosaic_figure(rows, out_dir / FIGURE, gaps_before=range(2, len(rows[0]), 2))
    return result
