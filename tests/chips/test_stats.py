"""`sasmi stats`: estimators on synthetic chips whose answer is known, the real chips, the CLI on renders."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage, stats as sps

from sasmi.cli.main import main
from sasmi.errors import SasmiError
from sasmi.images import write_gray
from sasmi.chips.stats import chip_statistics, find_target, floor_level, image_statistics, profile_swing
from sasmi.chips.compare import TOLERANCES, check, table

SIZE = 128
FLOOR = 0.25
LOOKS = 8.0


def speckle(rng, looks=LOOKS, shape=(SIZE, SIZE)) -> np.ndarray:
    """Gamma intensity speckle with mean 1 and `looks` looks (mean² / var = looks), white."""
    return rng.gamma(looks, 1.0 / looks, size=shape)


def target_chip(rng, highlight=(8, 6), shadow=(12, 30), at=(60, 58), shadow_level=0.1, left=False) -> np.ndarray:
    """Floor with a bright box (width along track, length along range) and a dark box right of it.

    `at` is the (row, col) of the highlight's top-left corner; left=True puts the shadow on the wrong side.
    """
    image = FLOOR * speckle(rng)
    r, c = at
    (hw, hl), (sw, sl) = highlight, shadow
    image[r:r + hw, c:c + hl] = 0.6 * rng.gamma(20.0, 1 / 20.0, size=(hw, hl))
    top = r + hw // 2 - sw // 2
    cols = slice(c - sl, c) if left else slice(c + hl, c + hl + sl)
    image[top:top + sw, cols] *= shadow_level
    return np.clip(image, 0.0, 1.0)


def test_known_boxes_on_known_speckle():
    rng = np.random.default_rng(0)
    s = image_statistics(target_chip(rng))
    assert abs(s["highlight_width"] - 8) <= 2 and abs(s["highlight_length"] - 6) <= 2
    assert abs(s["shadow_width"] - 12) <= 2 and abs(s["shadow_length"] - 30) <= 3
    assert 0.06 <= s["shadow_floor"] <= 0.14
    assert LOOKS * 0.85 <= s["looks"] <= LOOKS * 1.15
    assert abs(s["p50"] - 255 * FLOOR * sps.gamma(LOOKS, scale=1 / LOOKS).median()) <= 2.0
    assert abs(s["acf_range"]) < 0.05 and abs(s["acf_track"]) < 0.05
    assert abs(s["far_near"] - 1.0) < 0.05 and s["saturated"] == 0.0


def test_sizes_follow_the_boxes_and_scale_with_the_chip():
    rng = np.random.default_rng(1)
    small = image_statistics(target_chip(rng, highlight=(4, 4), shadow=(6, 12)))
    large = image_statistics(target_chip(rng, highlight=(14, 10), shadow=(24, 50), at=(52, 50)))
    assert abs(small["shadow_length"] - 12) <= 3 and abs(large["shadow_length"] - 50) <= 3
    assert abs(small["shadow_width"] - 6) <= 2 and abs(large["shadow_width"] - 24) <= 2
    assert abs(large["highlight_length"] - 10) <= 2 and abs(large["highlight_width"] - 14) <= 2
    big = target_chip(rng)  # the same scene at 256 px: sizes in pixels double
    halved = image_statistics(np.kron(big, np.ones((2, 2))))
    assert abs(halved["shadow_length"] - 60) <= 6 and abs(halved["highlight_width"] - 16) <= 4


def test_offset_along_track_is_the_highlight_rows_distance_from_the_centre_row():
    rng = np.random.default_rng(4)
    # an 8-row highlight whose top row is 60 spans rows 60-67, centred on 63.5 = (128 - 1) / 2
    centred = image_statistics(target_chip(rng, at=(60, 58)))["offset_track"]
    above = image_statistics(target_chip(rng, at=(49, 58)))["offset_track"]
    below = image_statistics(target_chip(rng, at=(72, 58)))["offset_track"]
    assert centred <= 1.0 and abs(above - 11) <= 1.5 and abs(below - 12) <= 1.5


def test_offset_along_range_is_the_highlight_columns_signed_distance_from_the_centre_column():
    rng = np.random.default_rng(5)
    # a 6-column highlight whose first column is 58 spans columns 58-63, centred on 60.5: 3 px nearer than 63.5
    near = image_statistics(target_chip(rng, at=(60, 58)))["offset_range"]
    nearer = image_statistics(target_chip(rng, at=(60, 48)))["offset_range"]
    farther = image_statistics(target_chip(rng, at=(60, 70)))["offset_range"]
    assert abs(near + 3) <= 1.0 and abs(nearer + 13) <= 1.0 and abs(farther - 9) <= 1.0


def test_no_target_means_nan_not_garbage():
    rng = np.random.default_rng(2)
    for image in (FLOOR * speckle(rng), target_chip(rng, left=True), target_chip(rng, at=(10, 10))):
        s = image_statistics(np.clip(image, 0, 1))
        assert find_target(image) is None
        assert all(math.isnan(s[k]) for k in ("shadow_length", "shadow_width", "highlight_length", "shadow_floor",
                                                  "offset_track", "offset_range"))
        assert math.isfinite(s["looks"]) and math.isfinite(s["p50"])


def test_correlated_speckle_and_range_falloff():
    rng = np.random.default_rng(3)
    # complex Gaussian field smoothed along range only: fully developed speckle correlated along range
    field = rng.normal(size=(SIZE, SIZE)) + 1j * rng.normal(size=(SIZE, SIZE))
    field = ndimage.uniform_filter1d(field.real, 3, axis=1) + 1j * ndimage.uniform_filter1d(field.imag, 3, axis=1)
    correlated = np.abs(field) ** 2
    s = image_statistics(np.clip(0.2 * correlated / correlated.mean(), 0, 1))
    assert s["acf_range"] > 0.3 and abs(s["acf_track"]) < 0.06
    ramp = np.linspace(1.0, 0.6, SIZE)[None, :]  # brightness falls with range (to the right)
    falloff = image_statistics(FLOOR * ramp * speckle(rng))
    expected = (1 - 0.4 * 5 / 6) / (1 - 0.4 / 6)
    assert abs(falloff["far_near"] - expected) < 0.04
    saturated = FLOOR * speckle(rng)
    saturated[:8, :16] = 1.0  # 128 px of 16384
    assert abs(image_statistics(saturated)["saturated"] - 100 * 128 / SIZE ** 2) < 0.05


def test_gain_swings_along_track_read_as_bands_and_a_target_or_range_fall_off_does_not():
    """Rows times exp(g), g smooth along track: the chip reads g's own swing; speckle alone, a target's rows
    and a fall-off along range read (nearly) none."""
    rng = np.random.default_rng(5)
    g = ndimage.gaussian_filter1d(rng.standard_normal(SIZE + 64), 8.0)[32:-32]
    g *= 0.12 / g.std()
    banded = image_statistics(FLOOR * np.exp(g)[:, None] * speckle(rng))["bands"]
    expected = profile_swing(g, np.ones(SIZE, bool), 1.0)
    assert banded == pytest.approx(expected, abs=0.015) and banded > 0.06, (banded, expected)
    # speckle correlated over two rows, as real speckle is along track (acf about 0.2 at 1 px): a lag of one
    # row reads its row medians' noise as a swing (median 0.025 over these chips), the lag of three does not
    def speckle_along_track():
        field = sum(np.abs(ndimage.uniform_filter1d(rng.normal(size=(SIZE, SIZE)), 2, axis=0)
                           + 1j * ndimage.uniform_filter1d(rng.normal(size=(SIZE, SIZE)), 2, axis=0)) ** 2
                    for _ in range(4))
        return field / field.mean()
    assert np.median([image_statistics(FLOOR * speckle_along_track())["bands"] for _ in range(12)]) < 0.01
    assert image_statistics(target_chip(rng))["bands"] < 0.02
    assert image_statistics(FLOOR * np.linspace(1.0, 0.6, SIZE)[None, :] * speckle(rng))["bands"] < 0.02


def test_speckle_grainier_in_patches_reads_as_contrast_wander_and_a_level_change_or_a_target_does_not():
    """A speckle whose deviations swing by exp(0.3 x a field smooth over 8 px) wanders well beyond a plain one's
    chance spread; a seabed brighter and darker in patches over a sonar's noise (its dark patches grainier, as their
    level explains) or a target's blocks do not."""
    rng = np.random.default_rng(6)

    def smooth_field() -> np.ndarray:
        field = ndimage.gaussian_filter(rng.standard_normal((SIZE, SIZE)), 8.0, mode="wrap")
        return field / field.std()

    plain = [image_statistics(FLOOR * speckle(rng))["wander"] for _ in range(6)]
    grainy = []
    for _ in range(6):
        s = speckle(rng)
        grainy.append(image_statistics(FLOOR * (1 + (s - 1) * np.exp(0.3 * smooth_field())).clip(0))["wander"])
    patchy = [image_statistics(np.clip(FLOOR * np.exp(0.6 * smooth_field()) * speckle(rng)
                                       + rng.normal(0.0, 0.04, (SIZE, SIZE)), 0, 1))["wander"] for _ in range(6)]
    targets = [image_statistics(target_chip(rng))["wander"] for _ in range(6)]
    assert np.median(plain) < 0.12 and np.median(grainy) > np.median(plain) + 0.12, (plain, grainy)
    assert abs(np.median(patchy) - np.median(plain)) < 0.05, (plain, patchy)
    assert abs(np.median(targets) - np.median(plain)) < 0.02, (plain, targets)


def test_a_seabed_brighter_and_darker_in_patches_raises_the_seabed_contrast_and_a_target_does_not():
    """A plain speckle's low-pass stays near its chance level; a seabed times exp(0.3 x a smooth field) stands out
    by about 0.3 above it; a target and its shadow, left out of the floor, add nothing."""
    rng = np.random.default_rng(7)
    field = ndimage.gaussian_filter(rng.standard_normal((SIZE, SIZE)), 8.0, mode="wrap")
    plain = [image_statistics(FLOOR * speckle(rng))["seabed"] for _ in range(4)]
    patchy = [image_statistics(FLOOR * np.exp(0.3 * field / field.std()) * speckle(rng))["seabed"] for _ in range(4)]
    targets = [image_statistics(target_chip(rng))["seabed"] for _ in range(4)]
    assert np.median(plain) < 0.06 and np.median(patchy) > np.median(plain) + 0.2, (plain, patchy)
    assert abs(np.median(targets) - np.median(plain)) < 0.02, (plain, targets)


def test_ripples_raise_the_floor_periodicity_and_banding_does_not():
    rng = np.random.default_rng(4)
    rows, cols = np.mgrid[:SIZE, :SIZE]
    plain = image_statistics(FLOOR * speckle(rng))["periodicity"]
    # sand ripples of 6 px wavelength, crests at 45°, modulating the backscatter by ±30 %
    ripples = 1.0 + 0.3 * np.sin(2 * np.pi * (rows + cols) / (6 * np.sqrt(2)))
    rippled = image_statistics(FLOOR * ripples * speckle(rng))["periodicity"]
    # the same stripes along track (constant in each range column): sonar banding, not ripples
    banding = 1.0 + 0.3 * np.sin(2 * np.pi * cols / 6)
    banded = image_statistics(FLOOR * banding * speckle(rng))["periodicity"]
    assert plain < 30 and banded < 30, (plain, banded)  # real chips: median 17
    assert rippled > 5 * plain, (rippled, plain)


def test_real_chips_targets_found_where_they_are(real_chips):
    targets = chip_statistics(real_chips / "targets", 128)
    seafloor = chip_statistics(real_chips / "seafloor", 128)
    assert targets["targets_found"] >= 0.75
    assert seafloor["targets_found"] <= 0.05
    assert 10 <= targets["summary"]["shadow_length"]["median"] <= 40  # real shadows run a few tens of px at 128 px
    assert 0.03 <= targets["summary"]["shadow_floor"]["median"] <= 0.25  # shadows are not black


@pytest.fixture(scope="module")
def renders(tmp_path_factory) -> Path:
    """8 chips of the shipped cylinder preset at 64 px, 4 spp."""
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import load_preset

    out = tmp_path_factory.mktemp("stats") / "renders"
    render_set(RenderJob(preset=load_preset(Path(__file__).resolve().parents[2] / "scenes" / "cylinder_chip.toml"),
                         out=out, count=8, size=64, spp=4), progress=False)
    return out


def test_cli_on_a_render_set(renders, tmp_path, capsys):
    rng = np.random.default_rng(4)
    synthetic = tmp_path / "synthetic"
    for i in range(6):
        write_gray(synthetic / f"{i}.png", target_chip(rng)[::2, ::2])
    out_json, out_png = tmp_path / "s.json", tmp_path / "s.png"
    assert main(["stats", str(synthetic), str(renders), "--size", "64", "--json", str(out_json),
                 "--plot", str(out_png)]) == 0
    printed = capsys.readouterr().out
    assert "shadow length along range" in printed and "median abs(image - mask)" in printed
    doc = json.loads(out_json.read_text())
    render_doc = doc["folders"][1]
    assert len(render_doc["per_chip"]["shadow_length"]) == 8
    assert render_doc["targets_found"] >= 0.75
    # the image estimate agrees with the mask within a few pixels at 64 px
    assert render_doc["mask_error"]["shadow_length"] <= 6 and render_doc["mask_error"]["shadow_width"] <= 6
    assert out_png.stat().st_size > 10_000


def test_check_and_bad_input(tmp_path, capsys):
    rng = np.random.default_rng(5)
    a, b = tmp_path / "a", tmp_path / "b"
    for i in range(4):
        write_gray(a / f"{i}.png", target_chip(rng))
        write_gray(b / f"{i}.png", np.clip(target_chip(rng, shadow=(24, 60), at=(52, 40)) * 1.8, 0, 1))
    ra, rb = chip_statistics(a), chip_statistics(b)
    assert all(check(ra, ra).values())
    failed = {k for k, ok in check(ra, rb).items() if not ok}
    assert {"shadow_length", "shadow_width", "p50"} <= failed and "looks" not in failed
    assert "**FAIL**" in table([ra, rb], with_check=True) and set(TOLERANCES) <= set(ra["summary"])
    assert main(["stats", str(a), str(b), "--check"]) == 1
    capsys.readouterr()
    (tmp_path / "empty").mkdir()
    with pytest.raises(SasmiError, match="no images"):
        chip_statistics(tmp_path / "empty")
    assert main(["stats", str(a), "--size", "100"]) == 2
    assert main(["stats", str(tmp_path / "nowhere")]) == 2
    assert "nowhere" in capsys.readouterr().err


def test_floor_level_over_a_mask_is_each_columns_median_there():
    """Each column's median over the masked pixels (odd and even counts), the other columns' median where a column
    has 8 or fewer, then smoothed along range: the definition, column by column."""
    rng = np.random.default_rng(0)
    for _ in range(20):
        image, where = rng.random((40, 30)), rng.random((40, 30)) < rng.uniform(0.1, 0.9)
        where[:, 3] = False  # a column with no floor pixel
        column = np.array([np.median(image[where[:, c], c]) if where[:, c].sum() > 8 else np.nan for c in range(30)])
        column[np.isnan(column)] = np.nanmedian(column)
        expected = np.maximum(ndimage.uniform_filter1d(column, size=9, mode="nearest"), 1 / 255)
        np.testing.assert_array_equal(floor_level(image, where), expected)


def test_speckle_looks_and_bands_are_those_of_each_whole_floor_block_and_row():
    from sasmi.chips.floor_texture import speckle_looks
    from sasmi.chips.stats import gain_swing

    rng = np.random.default_rng(9)
    image = rng.gamma(3.0, 1.0 / 3.0, (70, 90)) * np.linspace(0.2, 0.5, 70)[:, None] ** 2  # blocks differ in level
    floor = np.ones_like(image, dtype=bool)
    floor[5:30, 40:75] = False  # a target's box: the blocks it touches and the rows it shortens are left out
    looks = []  # the definition, block by block
    for r in range(0, 70 - 8 + 1, 8):
        for c in range(0, 90 - 8 + 1, 8):
            if floor[r:r + 8, c:c + 8].all():
                b = image[r:r + 8, c:c + 8]
                looks.append(b.mean() ** 2 / b.var(ddof=1))
    assert speckle_looks(image, floor, 8) == pytest.approx(np.median(looks), rel=1e-12)
    valid = floor.sum(axis=1) >= 90 // 4
    profile = [np.median(np.log(np.maximum(image[r][floor[r]], 1 / 255))) if valid[r] else 0.0 for r in range(70)]
    assert gain_swing(image, floor) == pytest.approx(profile_swing(np.array(profile), valid, 90 / 128), rel=1e-12)
