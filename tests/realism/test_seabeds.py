"""Seabeds drawn from real floors' statistics: the source's range profile and directions kept, no source copied,
one stream per chip, and a seabeds file that fails in one line; renders laid on them keep their labels."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from sasmi.errors import SasmiError
from sasmi.images import write_gray
from sasmi.realism.floors import on_floor, onto_seabed_floors, render_speckle, seabed_floor
from sasmi.realism.seabeds import COARSE, draw_seabed, fit_seabeds, load_seabeds, log_seabed, save_seabeds

SIZE = 128


def _banded_floors(folder, n=6, seed=0):
    """Floor chips brighter towards far range (x), with bands along track (rows) and speckle."""
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 1.0, SIZE)
    for i in range(n):
        bands = 1.0 + 0.5 * np.sin(np.arange(SIZE) / 6.0 + rng.uniform(0, 6))[:, None]  # rows differ, columns alike
        level = (0.15 + 0.2 * x)[None, :] * bands
        write_gray(folder / f"floor_{i}.png", np.clip(level * rng.gamma(8, 1 / 8, (SIZE, SIZE)), 0, 1))
    return folder


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
    for i in range(10):
        drawn = _rest(log_seabed(draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng(i)))).ravel()
        assert max(abs(np.corrcoef(drawn, source)[0, 1]) for source in sources) < 0.8  # new phases: no source


def test_seabed_floor_keeps_the_renders_speckle_under_a_new_seabed(seabeds):
    rng = np.random.default_rng(0)
    mask = np.zeros((SIZE, SIZE), np.uint8)
    mask[60:68, 40:48], mask[60:68, 48:80] = 1, 2
    speckle = rng.gamma(4, 1 / 4, (SIZE, SIZE))
    render = np.clip(0.3 * speckle, 0, 1).astype(np.float32)
    render[mask == 1], render[mask == 2] = 0.9, 0.03
    own = render_speckle(render.astype(np.float64), mask)
    assert own[mask == 0].mean() == pytest.approx(1.0, abs=0.05)  # over its own seabed, the target not mixed in
    assert (own[mask > 0] == 1.0).all()
    floor = seabed_floor(seabeds, render, mask, 0, 5)
    np.testing.assert_array_equal(floor, seabed_floor(seabeds, render, mask, 0, 5))  # (seed, index) alone
    seabed = draw_seabed(seabeds, (SIZE, SIZE), np.random.default_rng([0, 5]))
    ratio = floor[mask == 0] / own[mask == 0]  # the floor over the render's speckle: the seabed, banded
    assert np.corrcoef(ratio, seabed[mask == 0])[0, 1] > 0.9
    out = on_floor(render, mask, floor)
    assert np.median(out[mask == 2]) < 0.3 * np.median(out[mask == 0])  # the shadow stays dark on it


def test_renders_on_seabed_floors_keep_their_labels(seabeds, render_set, tmp_path):
    out = tmp_path / "on_seabeds"
    assert onto_seabed_floors(render_set, seabeds, out, 32, seed=1) == 8
    labels = [json.loads(line) for line in (out / "labels.jsonl").read_text().splitlines()]
    rendered = [json.loads(line) for line in (render_set / "labels.jsonl").read_text().splitlines()]
    assert [label["targets"] for label in labels] == [label["targets"] for label in rendered]
    assert [label.get("clutter") for label in labels] == [label.get("clutter") for label in rendered]  # rocks stay
    assert labels[3]["floor"] == {"seabeds": None, "seabed_stream": [1, 3]}


def test_seabeds_file_round_trip_and_bad_files(seabeds, tmp_path):
    path = save_seabeds(seabeds, tmp_path / "seabeds.pt", {"note": "test"})
    loaded = load_seabeds(path)
    np.testing.assert_allclose(loaded.amplitude, seabeds.amplitude, rtol=1e-6)
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
