"""The plain-statistics two-sample test: nothing telling between two draws of one distribution; a set whose
speckle contrast wanders, or whose highlights are brighter, named by that statistic."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from sasmi.eval.signature import STATISTICS, chip_statistics, signature, signature_markdown

SIZE = 64


def _floors(n, seed, wander=0.0, highlight=0.0):
    """(n, S, S) uint8 grainy gamma speckle at level 0.3; `wander` makes its contrast stray over 4 px patches,
    `highlight` puts a small target of that brightness in each chip."""
    rng = np.random.default_rng(seed)
    speckle = ndimage.gaussian_filter1d(rng.gamma(4.0, 0.25, (n, SIZE, SIZE)), 0.8, axis=2)
    field = ndimage.gaussian_filter(rng.standard_normal((n, SIZE, SIZE)), (0, 4, 4))
    field /= field.std(axis=(1, 2), keepdims=True)
    x = 0.3 * (1.0 + (speckle - 1.0) * np.exp(wander * field - wander ** 2))  # its mean square kept
    if highlight:
        x[:, 30:33, 30:33] = highlight
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def test_every_statistic_is_measured_on_every_chip():
    stats = chip_statistics(_floors(5, 0))
    assert set(stats) == set(STATISTICS) and all(v.shape == (5,) and np.isfinite(v).all() for v in stats.values())


def test_two_draws_of_one_distribution_tell_nothing():
    result = signature(_floors(120, 0), _floors(120, 1))
    assert all(0.35 < row["auc"] < 0.65 for row in result["statistics"]), result["statistics"]
    assert 0.3 < result["all_together"] < 0.7


def test_a_wandering_contrast_is_named_first():
    result = signature(_floors(120, 0), _floors(120, 1, wander=0.2))
    first = result["statistics"][0]
    assert first["statistic"] == "contrast wander" and first["auc"] > 0.85 and first["set"] > first["real"]
    assert result["all_together"] > 0.85


def test_brighter_highlights_are_named_and_shown():
    result = signature(_floors(60, 0, highlight=0.7), _floors(60, 1, highlight=1.0))
    assert result["statistics"][0]["statistic"] == "bright tail" and result["statistics"][0]["auc"] > 0.9
    text = signature_markdown({"brighter": result})
    assert "| brighter |" in text and "bright tail" in text.splitlines()[-1]


def test_contrast_that_follows_the_level_is_not_called_wander():
    """Patches of a floor darker and grainier (as a sonar's noise makes them) stray by their level alone."""
    rng = np.random.default_rng(2)
    level = np.exp(3.2 * ndimage.gaussian_filter(rng.standard_normal((120, SIZE, SIZE)), (0, 4, 4)))  # 0.7-1.5 ×
    level /= np.median(level, axis=(1, 2), keepdims=True)

    def floor(seed, slope):
        """`_floors`' speckle (mean 1) under that level, its deviations grown by level ** slope."""
        speckle = _floors(120, seed).astype(np.float64) / (0.3 * 255)
        return np.clip(0.3 * level * (1.0 + (speckle - 1.0) * level ** slope), 0, 1)

    plain, grainy = floor(0, 0.0), floor(1, -0.5)
    wander = next(row for row in signature(plain, grainy)["statistics"] if row["statistic"] == "contrast wander")
    assert 0.3 < wander["auc"] < 0.7, wander
