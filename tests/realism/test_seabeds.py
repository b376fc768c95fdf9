"""Floors drawn from real floors' statistics: the source's range profile, directions, relief, speckle grain, gray
levels, speckle contrast against level and its wander kept, no source copied, one stream per chip, and a seabeds
file that fails in one line; renders laid on them keep their labels."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from scipy import ndimage

from sasmi.errors import SasmiError
from sasmi.images import write_gray
from sasmi.realism.floors import on_floor, onto_seabed_floors, seabed_floor
from sasmi.realism.seabeds import (SEABED, _block_contrast, _unexplained, contrast_slope, draw_floor, draw_seabed,
                                   draw_speckle, fit_seabeds, load_seabeds, log_seabed, save_seabeds, seabed_of,
                                   speckle_of, WANDER_LENGTH)
from sasmi.render.post import wander_field, wandered

SIZE = 128


def _grainy_speckle(rng):
    """Speckle with a grain: correlated over about a pixel along range (columns), not along track."""
    return ndimage.gaussian_filter1d(rng.gamma(2, 1 / 2, (SIZE, SIZE)), 1.0, axis=1)


def _banded_floors(folder, n=6, seed=0):
    """Floor chips brighter towards far range (x), with bands along track (rows) and grainy speckle."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 1.0, SIZE)
    for i in range(n):
        bands = 1.0 + 0.5 * np.sin(np.arange(SIZE) / 6.0 + rng.uniform(0, 6))[:, None]  # rows differ, columns alike
        level = (0.15 + 0.2 * x)[None, :] * bands
        write_gray(folder / f"floor_{i}.png", np.clip(level * _grainy_speckle(rng), 0, 1))
    return folder


def _lag1(x, axis):
    """The autocorrelation at one pixel along `axis` (1: range, 0: along track)."""
    x = x - x.mean()
    return float((x * np.roll(x, 1, axis=axis)).mean() / x.var())


@pytest.fixture(scope="module")
def seabeds(tmp_path_factory):
    return fit_seabeds(_banded_floors(tmp_path_factory.mktemp("floors")))


def test_a_drawn_seabed_keeps_its_sources_profile_and_direction(seabeds):
    logs = np.stack([log_seabed(draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng(i))) for i in range(20)])
    profile = logs.mean(axis=1)  # (20, COARSE) along range
    assert (profile[:, -4:].mean(1) - profile[:, :4].mean(1) > 0.6).all()  # far range brighter, as every source
    along_track = logs.mean(axis=2).std(axis=1).mean()   # the bands: row means differ
    across = (logs - logs.mean(axis=1, keepdims=True)).mean(axis=1).std(axis=1).mean()  # column means, profile removed
    assert along_track > 5 * max(across, 1e-6)


def _rest(log):
    return log - log.mean(axis=0, keepdims=True)  # less the mean and the range profile


def test_drawn_seabeds_copy_no_source_and_follow_their_stream(seabeds, tmp_path_factory):
    a = draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng([3, 7]))
    np.testing.assert_array_equal(a, draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng([3, 7])))
    assert not np.allclose(a, draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng([3, 8])))
    folder = _banded_floors(tmp_path_factory.mktemp("again"))
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    sources = [_rest(log_seabed(load_image(p, SIZE))).ravel() for p in list_images(folder)]
    nearest = []
    for i in range(10):
        drawn = _rest(log_seabed(draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng(i)))).ravel()
        nearest.append(max(abs(np.corrcoef(drawn, source)[0, 1]) for source in sources))
    # new phases: no source (a copy scores 1; a draw of these pure sine bands may chance near one source)
    assert max(nearest) < 0.9 and np.mean(nearest) < 0.7


def test_drawn_floors_have_their_sources_relief(seabeds, tmp_path_factory):
    """A drawn seabed is its source's seabed (a chip blurred over SEABED px) under new phases, not blurred again:
    seen as a chip is (`log_seabed`, which blurs once more), a drawn floor swings as much as its source so seen."""
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    relief = lambda chip: _rest(log_seabed(chip)).std()
    folder = _banded_floors(tmp_path_factory.mktemp("relief"))
    seabeds_seen = [relief(ndimage.gaussian_filter(load_image(p, SIZE).astype(np.float64), SEABED))
                    for p in list_images(folder)]
    drawn = [relief(draw_floor(seabeds, (SIZE, SIZE), np.random.default_rng(i))) for i in range(20)]
    assert np.mean(drawn) == pytest.approx(np.mean(seabeds_seen), rel=0.08)  # blurred twice: 16 % less


def test_drawn_speckle_has_its_sources_grain_and_levels(seabeds, tmp_path_factory):
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    sources = [speckle_of(load_image(p, SIZE).astype(np.float64))
               for p in list_images(_banded_floors(tmp_path_factory.mktemp("grain")))]
    drawn = [draw_speckle(seabeds, k, np.random.default_rng(k)) for k in range(len(sources))]
    for source, speckle in zip(sources, drawn):
        np.testing.assert_allclose(np.percentile(speckle, [5, 50, 95]), np.percentile(source, [5, 50, 95]), rtol=0.03)
        assert _lag1(speckle, 1) == pytest.approx(_lag1(source, 1), abs=0.1)   # the grain along range ...
        assert _lag1(speckle, 0) == pytest.approx(_lag1(source, 0), abs=0.1)   # ... and none along track
        assert _lag1(source, 1) > 0.4 + _lag1(source, 0)                       # (the sources have one)
        assert abs(np.corrcoef(speckle.ravel(), source.ravel())[0, 1]) < 0.2  # new phases: not the source


def _coherent_floors(folder, n=6, seed=4):
    """Floor chips of fully developed speckle: |z|² of a complex Gaussian field blurred by a small PSF."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        z = rng.standard_normal((2, SIZE, SIZE))
        intensity = sum(ndimage.gaussian_filter(part, (0.4, 0.8)) ** 2 for part in z)
        write_gray(folder / f"floor_{i}.png", np.clip(0.2 * intensity / intensity.mean(), 0, 1))
    return folder


def _grains(x):
    """The correlation of neighbouring pixels' squared deviations along range: bright pixels in grains."""
    d = (x - x.mean()) ** 2
    return _lag1(d, 1)


def test_drawn_speckle_keeps_its_sources_bright_grains(tmp_path):
    """Bright speckle pixels come in grains (a coherent sonar's intensity); a speckle of the same spectrum and
    levels from shuffled pixels scatters them among dim ones (about 0.2 here against the source's 0.29)."""
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    folder = _coherent_floors(tmp_path)
    fitted = fit_seabeds(folder)
    sources = [_grains(speckle_of(load_image(p, SIZE).astype(np.float64))) for p in list_images(folder)]
    drawn = [_grains(draw_speckle(fitted, k, np.random.default_rng(k))) for k in range(len(sources))]
    assert np.mean(drawn) == pytest.approx(np.mean(sources), abs=0.05)


def test_speckle_grains_benchmark_tells_grains_from_a_shuffle_and_names_a_bad_folder(tmp_path, capsys, monkeypatch):
    """benchmarks/speckle_grains.py: a coherent speckle shows grains that a speckle of its grain and levels drawn
    from shuffled levels lacks; lone bright pixels are counted in the rows asked; an empty --real folder gets one
    line and exit 2."""
    import sys

    from conftest import benchmark

    bench = benchmark("speckle_grains")
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    floors = _coherent_floors(tmp_path / "floors", n=2)
    fitted = fit_seabeds(floors)
    rows = np.arange(SIZE)
    source = speckle_of(load_image(list_images(floors)[0], SIZE).astype(np.float64))
    # the same grain (linear correlation) and levels, from shuffled levels: fewer grains
    shuffled = [draw_speckle(fitted, 0, np.random.default_rng(k), coherent=False) for k in range(3)]
    assert bench.grains(source, rows) > max(bench.grains(x, rows) for x in shuffled) + 0.05
    flat = 1.0 + 0.1 * np.random.default_rng(6).random((SIZE, SIZE))
    flat[8:120:8, 8] = 5.0                      # 14 lone bright pixels, 8 px apart; those in rows 0-63 counted
    assert bench.isolated(flat, np.arange(64)) == 7
    seabeds = save_seabeds(fitted, tmp_path / "seabeds.pt")
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setattr(sys, "argv", ["speckle_grains.py", "--seabeds", str(seabeds), "--real", str(empty)])
    assert bench.main() == 2
    assert "--real" in capsys.readouterr().err


def test_target_chips_give_the_speckle_of_their_floor_not_of_their_target(tmp_path):
    """Target chips (a bright target and a black shadow across the centre rows) lend their floor's speckle alone."""
    rng = np.random.default_rng(1)
    floors, targets = _banded_floors(tmp_path / "floors"), tmp_path / "targets"
    clean = []
    for i in range(4):
        chip = np.clip(0.3 * _grainy_speckle(rng), 0, 1)
        clean.append(speckle_of(chip))
        chip[54:74, 30:50], chip[54:74, 50:110] = 1.0, 0.0  # target and shadow, as `sasmi stats` sees them
        write_gray(targets / f"target_{i}.png", chip)
    fitted = fit_seabeds(floors, targets)
    assert len(fitted.mean) == 6 and len(fitted.speckle_levels) == 4
    floor_levels = np.quantile(np.concatenate([c.ravel() for c in clean]), [0.01, 0.5, 0.99])
    got = np.quantile(fitted.speckle_levels, [0.01, 0.5, 0.99], axis=1).mean(axis=1)
    np.testing.assert_allclose(got, floor_levels, rtol=0.1)  # neither the target's tail nor the shadow's zeros
    drawn = draw_speckle(fitted, 0, np.random.default_rng(0))
    assert _lag1(drawn, 1) == pytest.approx(_lag1(clean[0], 1), abs=0.1)  # the floor's grain, not the edges'


def _grainier_in_the_dark(folder, slope, n=6, seed=2):
    """Banded floor chips whose speckle's deviations grow as (level / median)^slope: contrast falling with level.
    Their levels are a real chip's: a floor around 0.15 and one pixel, alone, at the display's top."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        level = 0.15 * np.exp(0.6 * np.sin(np.arange(SIZE) / 9.0 + rng.uniform(0, 6)))[:, None] * np.ones(SIZE)
        speckle = _grainy_speckle(rng)
        mean = speckle.mean()
        grain = mean + (speckle - mean) * (level / np.median(level)) ** slope
        chip = np.clip(level * grain, 0, 1)
        chip[rng.integers(SIZE), rng.integers(SIZE)] = 0.92
        write_gray(folder / f"floor_{i}.png", chip)
    return folder


def test_drawn_floors_keep_how_their_sources_speckle_contrast_follows_the_level(tmp_path):
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    everywhere = np.ones((SIZE, SIZE), bool)
    for slope in (-0.5, 0.0):
        folder = _grainier_in_the_dark(tmp_path / f"slope{slope}", slope)
        measured = [contrast_slope(load_image(p, SIZE).astype(np.float64), everywhere) for p in list_images(folder)]
        assert np.median(measured) == pytest.approx(slope, abs=0.1)
        fitted = fit_seabeds(folder)
        np.testing.assert_allclose(fitted.speckle_slope, measured)
        drawn = [contrast_slope(np.clip(draw_floor(fitted, (SIZE, SIZE), np.random.default_rng(i)), 0, 1), everywhere)
                 for i in range(12)]
        assert np.median(drawn) == pytest.approx(np.median(measured), abs=0.07)  # the bend steepens it a little


def _wandering_floors(folder, wander, n=6, seed=3):
    """Flat floor chips whose grainy speckle's contrast wanders over patches by `wander` (0: the same everywhere)."""
    rng = np.random.default_rng(seed)
    for i in range(n):
        speckle = wandered(_grainy_speckle(rng), wander, wander_field((SIZE, SIZE), rng, WANDER_LENGTH))
        write_gray(folder / f"floor_{i}.png", np.clip(0.3 * speckle, 0, 1))
    return folder


def _contrast_spread(chip):
    """How much the log contrast of a floor's 8 px blocks spreads beyond what their level explains."""
    return _unexplained(*_block_contrast(speckle_of(chip), seabed_of(chip), np.ones(chip.shape, bool)))


def test_drawn_floors_keep_how_much_their_sources_speckle_contrast_wanders(tmp_path):
    from sasmi.images import list_images
    from sasmi.preprocess import load_image

    spreads = {}
    for wander in (0.0, 0.3):
        folder = _wandering_floors(tmp_path / f"wander{wander}", wander)
        fitted = fit_seabeds(folder)
        assert np.median(fitted.speckle_wander) == pytest.approx(wander, abs=0.06)
        sources = [_contrast_spread(load_image(p, SIZE).astype(np.float64)) for p in list_images(folder)]
        drawn = [_contrast_spread(np.clip(draw_floor(fitted, (SIZE, SIZE), np.random.default_rng(i)), 0, 1))
                 for i in range(12)]
        assert np.median(drawn) == pytest.approx(np.median(sources), rel=0.15)
        spreads[wander] = np.median(sources)
    assert spreads[0.3] > 1.3 * spreads[0.0]  # (the wander shows in the spread)


def test_drawn_floors_stay_under_their_speckle_chips_brightest_level(tmp_path):
    """Bright floors whose brightest pixel is 0.8: a seabed times a speckle drawn from them would pass it (and clip
    to white in clusters); bent, every drawn floor stays under it and few pixels come near it, as in the sources."""
    rng = np.random.default_rng(4)
    folder = tmp_path / "bright"
    for i in range(6):
        chip = np.minimum(0.25 * _grainy_speckle(rng), 0.8)
        chip[rng.integers(SIZE), rng.integers(SIZE)] = 0.8
        write_gray(folder / f"floor_{i}.png", chip)
    fitted = fit_seabeds(folder)
    np.testing.assert_allclose(fitted.speckle_ceiling, 0.8, atol=1 / 255)
    floors = np.stack([draw_floor(fitted, (SIZE, SIZE), np.random.default_rng(i)) for i in range(8)])
    assert floors.max() < 0.8
    assert (floors > 0.75).mean() < 0.01
    assert np.median(floors) == pytest.approx(np.median(0.25 * _grainy_speckle(rng)), rel=0.2)  # the bulk unbent


def test_seabed_floor_replaces_the_renders_speckle_with_a_drawn_one(seabeds):
    rng = np.random.default_rng(0)
    mask = np.zeros((SIZE, SIZE), np.uint8)
    mask[60:68, 40:48], mask[60:68, 48:80] = 1, 2
    speckle = rng.gamma(4, 1 / 4, (SIZE, SIZE))
    render = np.clip(0.3 * speckle, 0, 1).astype(np.float32)
    render[mask == 1], render[mask == 2] = 0.9, 0.03
    floor = seabed_floor(seabeds, render.shape, 0, 5)
    np.testing.assert_array_equal(floor, seabed_floor(seabeds, render.shape, 0, 5))  # (seed, index) alone
    assert not np.array_equal(floor, seabed_floor(seabeds, render.shape, 0, 6))
    assert abs(np.corrcoef(floor.ravel(), render.ravel())[0, 1]) < 0.1   # nothing of the render's speckle
    assert _lag1(floor, 1) > 0.3 + _lag1(render, 1)                      # the sources' grain instead
    out = on_floor(render, mask, floor)
    assert np.median(out[mask == 2]) < 0.3 * np.median(out[mask == 0])  # the shadow stays dark on it


def test_renders_on_seabed_floors_keep_their_labels(seabeds, render_set, tmp_path):
    out = tmp_path / "on_seabeds"
    assert onto_seabed_floors(render_set, seabeds, out, 32, seed=1) == 8
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    rendered = [json.loads(line) for line in (render_set / "labels.jsonl").read_text().splitlines()]
    assert [label["targets"] for label in labels] == [label["targets"] for label in rendered]
    assert all(not label.get("clutter") for label in labels)  # the rendered rocks went with the render's speckle
    assert labels[3]["floor"] == {"seabeds": None, "seabed_stream": [1, 3]}


def test_seabeds_file_round_trip_and_bad_files(seabeds, tmp_path):
    path = save_seabeds(seabeds, tmp_path / "seabeds.pt", {"note": "test"})
    loaded = load_seabeds(path)
    for table in ("amplitude", "speckle_power", "speckle_levels", "speckle_slope", "speckle_wander", "speckle_ceiling"):
        np.testing.assert_allclose(getattr(loaded, table), getattr(seabeds, table), rtol=1e-6, atol=1e-7)
    assert loaded.path == path
    torch.load(path, weights_only=True)  # tensors and plain types only
    bad = tmp_path / "bad.pt"
    bad.write_bytes(path.read_bytes()[:100])
    with pytest.raises(SasmiError, match="bad.pt: not a readable seabeds file"):
        load_seabeds(bad)
    data = torch.load(path, weights_only=True)
    for change, message in (({"format": 99}, "format 99"), ({"kind": "dcgan"}, "not a seabeds file"),
                            ({"state": {"mean": data["state"]["mean"]}}, "missing or of the wrong shape")):
        torch.save({**data, **change}, bad)
        with pytest.raises(SasmiError, match=message):
            load_seabeds(bad)
    with pytest.raises(SasmiError, match="no such seabeds file"):
        load_seabeds(tmp_path / "none.pt")
    older = tmp_path / "older.pt"  # a file without the wander and ceiling tables: drawn without wander, unbent
    torch.save({**data, "state": {k: v for k, v in data["state"].items()
                                  if k not in ("speckle_wander", "speckle_ceiling")}}, older)
    np.testing.assert_array_equal(load_seabeds(older).speckle_wander, np.zeros(len(seabeds.speckle_wander)))
    assert np.isinf(load_seabeds(older).speckle_ceiling).all()
