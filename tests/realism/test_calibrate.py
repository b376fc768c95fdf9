"""`sasmi calibrate`: the knobs write the presets they say, the objective's distances, and a search that
recovers a known preset's gain from its own renders, continues when rerun and refuses other settings."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import tomllib
from dataclasses import replace

import numpy as np
import pytest
from PIL import Image

from sasmi.chips.compare import TOLERANCES, Tolerance
from sasmi.chips.stats import MASK_STATISTICS
from sasmi.errors import SasmiError
from sasmi.realism.calibrate import CalibrateConfig, calibrate, render_chips
from sasmi.realism.calibration_objective import (Weights, auc_tolerance, found_tolerance, phi_references, real_chips,
                                                 score, spread_corrected_fid, told_apart)
from sasmi.realism.preset_space import (DEFAULT_KNOBS, KNOBS, apply, centre, check_knobs, named_knobs, spread,
                                       start_values)
from sasmi.scene.preset import Preset, load_preset, shipped_presets


@pytest.mark.parametrize("name", shipped_presets())
def test_start_values_rebuild_the_start_preset(name):
    """Setting every knob to its start value leaves each field's centre where it was (within the knob's
    range and 4 digits), and the result is a valid preset."""
    preset = load_preset(name)
    values = start_values(preset.raw, DEFAULT_KNOBS)
    raw = apply(preset.raw, values)
    Preset.from_dict(raw)
    for knob_name, value in values.items():
        if knob_name.startswith("targets.") or knob_name.endswith(".spread"):
            continue
        section, key = knob_name.split(".")
        if key in preset.raw.get(section, {}) and KNOBS[knob_name].low <= centre(preset.raw[section][key]) \
                <= KNOBS[knob_name].high and not KNOBS[knob_name].whole:
            assert centre(raw[section][key]) == pytest.approx(centre(preset.raw[section][key]), rel=1e-3), knob_name


def test_knobs_move_the_fields_they_name():
    raw = load_preset("cylinder_chip").raw
    moved = apply(raw, {"post.gain": 0.2, "post.gain.spread": 0.5, "targets.size": 2.0, "sonar.near_range": 80.0,
                        "targets.track_offset": 0.25})
    assert moved["post"]["gain"] == {"uniform": [0.1, 0.3]}
    assert spread(moved["post"]["gain"]) == pytest.approx(0.5)
    for before, after in zip(raw["targets"], moved["targets"]):
        for key in ("length", "radius", "width", "height"):
            if key in before:
                assert centre(after[key]) == pytest.approx(2 * centre(before[key]), rel=1e-3)
        assert after["yaw"] == before["yaw"] if "yaw" in before else True
        assert after["x"] == before["x"] if "x" in before else True
        if "y" in before:  # a normal's mean and sd, or a uniform's ends, a quarter as far from the centre row
            assert next(iter(after["y"].values())) == pytest.approx([v / 4 for v in next(iter(before["y"].values()))])
    far = max(moved["sonar"]["near_range"]["uniform"]) + moved["sonar"]["chip_size"]
    assert moved["sonar"]["max_range"] >= far  # the chip stays in range
    assert raw["post"]["gain"] == {"uniform": [0.22, 0.68]}  # the start is not changed in place


def test_the_length_knob_scales_lengths_alone_on_top_of_the_size():
    raw = load_preset("cylinder_chip").raw
    moved = apply(raw, {"targets.size": 2.0, "targets.length": 0.25})
    Preset.from_dict(moved)
    lengths = 0
    for before, after in zip(raw["targets"], moved["targets"]):
        if "length" in before:  # cylinders and boxes: twice as thick, half as long
            lengths += 1
            assert centre(after["length"]) == pytest.approx(0.5 * centre(before["length"]), rel=1e-3)
        for key in ("radius", "width", "height", "tube_radius"):
            if key in before:
                assert centre(after[key]) == pytest.approx(2 * centre(before[key]), rel=1e-3), key
    assert lengths >= 2  # the cylinders and boxes at least


def test_targets_keep_their_place_in_a_moved_chip_and_the_range_offset_moves_them_along_range_alone():
    raw = load_preset("muscle_paper").raw  # a 6 m chip, targets -1 to 0 m along range, -0.8 to 0.8 m along track
    grown = apply(raw, {"sonar.chip_size": 24.0})
    assert grown["targets"][0]["x"] == {"uniform": [-4.0, 0.0]} and grown["targets"][0]["y"] == {"uniform": [-3.2, 3.2]}
    nearer = apply(raw, {"targets.range_offset": 2.0})
    assert nearer["targets"][0]["x"] == {"uniform": [-2.0, 0.0]} and nearer["targets"][0]["y"] == raw["targets"][0]["y"]
    both = apply(raw, {"sonar.chip_size": 24.0, "targets.range_offset": 0.5, "targets.track_offset": 0.25})
    assert both["targets"][0]["x"] == {"uniform": [-2.0, 0.0]} and both["targets"][0]["y"] == {"uniform": [-0.8, 0.8]}
    Preset.from_dict(both)


def test_altitude_is_written_out_before_the_range_moves():
    raw = load_preset("muscle_paper").raw  # no altitude: max_range / 10 = 6 m
    moved = apply(raw, {"sonar.chip_size": 40.0})
    assert moved["sonar"]["altitude"] == 6.0 and moved["sonar"]["max_range"] > 60


def test_spread_only_keeps_the_centre():
    raw = load_preset("cylinder_chip").raw
    moved = apply(raw, {"seafloor.albedo.spread": 0.0})
    assert moved["seafloor"]["albedo"] == pytest.approx(0.35)
    assert apply({}, {"post.gain.spread": 0.3})["post"]["gain"] == {"uniform": [0.315, 0.585]}  # the default 0.45


def test_unknown_and_repeated_knobs_are_refused():
    with pytest.raises(SasmiError, match="unknown parameter post.gian"):
        check_knobs(("post.gian",))
    with pytest.raises(SasmiError, match="twice"):
        check_knobs(("post.gain", "post.gain"))
    with pytest.raises(SasmiError, match="unknown parameter targets.size.spread"):
        check_knobs(("targets.size.spread",))


def test_default_in_params_stands_for_the_default_knobs():
    assert named_knobs("default") == DEFAULT_KNOBS
    assert named_knobs(" post.gain , sonar.altitude,") == ("post.gain", "sonar.altitude")
    assert named_knobs("default,post.tvg_strength.spread") == (*DEFAULT_KNOBS, "post.tvg_strength.spread")
    # ripples, the floor's patches, a second sediment and the targets' aspect are searched where named, and their
    # knobs write a valid preset
    named = {"seafloor.ripple_amplitude", "seafloor.ripple_wavelength", "seafloor.ripple_direction",
             "seafloor.ripple_sinuosity", "seafloor.ripple_sharpness", "seafloor.patchiness", "seafloor.patch_size",
             "seafloor.mosaic_contrast", "seafloor.mosaic_share", "seafloor.mosaic_size", "targets.length"}
    assert not named & set(DEFAULT_KNOBS)
    names = check_knobs(named_knobs("default,seafloor.patchiness,seafloor.patch_size"))
    raw = apply(load_preset("seafloor_only").raw, {"seafloor.patchiness": 0.6, "seafloor.patch_size": 4.0,
                                                   "seafloor.patchiness.spread": 0.5})
    assert names[-2:] == ("seafloor.patchiness", "seafloor.patch_size")
    assert raw["seafloor"]["patchiness"] == {"uniform": [0.3, 0.9]} and raw["seafloor"]["patch_size"] == 4.0
    Preset.from_dict(raw)
    raw = apply(load_preset("seafloor_only").raw, {"seafloor.ripple_amplitude": 0.08, "seafloor.ripple_direction": 10.0,
                                                   "seafloor.ripple_sinuosity": 0.1, "seafloor.ripple_sharpness": 4.0,
                                                   "seafloor.mosaic_contrast": 0.3, "seafloor.mosaic_share": 0.4,
                                                   "seafloor.mosaic_size": 8.0})
    floor = raw["seafloor"]
    assert floor["ripple_amplitude"] == {"choice": [0.0, 0.08, 0.16]}  # the start's draws, scaled
    assert floor["ripple_direction"] == {"uniform": [0.0, 20.0]}  # the start's spread kept: [0, 2 x centre]
    assert (floor["mosaic_contrast"], floor["mosaic_share"], floor["mosaic_size"]) == (0.3, 0.4, 8.0)
    assert floor["ripple_sharpness"] == 4.0
    Preset.from_dict(raw).sample(0, 0)
    with pytest.raises(SasmiError, match="twice"):
        check_knobs(named_knobs("default,post.gain.spread"))


def test_knobs_on_seafloor_kinds_set_every_kind_or_the_one_they_name():
    raw = load_preset("seafloor_mixed").raw  # three kinds: sand waves, rippled sand, two sediments
    names = check_knobs(("seafloor.albedo", "seafloor[0].ripple_amplitude", "seafloor[2].weight",
                         "seafloor[2].mosaic_contrast.spread"))
    x0 = start_values(raw, names)
    assert x0 == pytest.approx({"seafloor.albedo": 0.45, "seafloor[0].ripple_amplitude": 0.1, "seafloor[2].weight": 1.0,
                                "seafloor[2].mosaic_contrast.spread": 1 / 3})
    moved = apply(raw, {"seafloor.albedo": 0.2, "seafloor[0].ripple_amplitude": 0.05, "seafloor[2].weight": 3.0,
                        "seafloor[2].mosaic_contrast.spread": 0.0})
    kinds = moved["seafloor"]
    assert [k["albedo"] for k in kinds] == [{"uniform": [0.1333, 0.2667]}] * 3  # every kind, each keeping its spread
    assert kinds[0]["ripple_amplitude"] == {"uniform": [0.025, 0.075]}
    assert kinds[1]["ripple_amplitude"] == raw["seafloor"][1]["ripple_amplitude"]  # another kind's field stays
    assert kinds[2]["mosaic_contrast"] == 0.45 and kinds[2]["weight"] == 3.0
    assert "weight" not in kinds[1] or kinds[1]["weight"] == 1.0
    floors = [Preset.from_dict(moved).sample(0, i).seafloor for i in range(300)]
    assert 0.52 < np.mean([f.mosaic_contrast != 1 for f in floors]) < 0.68  # 3 / (1 + 1 + 3)
    for names, words in ((("seafloor[3].albedo",), "has 3 [[seafloor]] kinds"),
                         (("seafloor[0].weight.spread",), "unknown parameter seafloor[0].weight.spread")):
        with pytest.raises(SasmiError, match=re.escape(words)):
            start_values(raw, check_knobs(names))
    with pytest.raises(SasmiError, match=re.escape("one [seafloor] table (allowed: seafloor.albedo")):
        start_values(load_preset("seafloor_only").raw, ("seafloor[0].albedo",))
    with pytest.raises(SasmiError, match=re.escape("seafloor[1].albedo and seafloor.albedo (every kind alike)")):
        check_knobs(("seafloor.albedo", "seafloor[1].albedo"))


def test_renders_grouped_by_structure_land_at_their_scene_index():
    """A trial's renders come out in scene order, whatever order they were rendered in."""
    from sasmi.render.mitsuba import render

    preset, cfg = load_preset("cylinder_chip"), CalibrateConfig(size=32, spp=2)
    images = render_chips(preset, 6, cfg, seed=0)
    for i in range(6):
        alone = render(preset.sample(0, i), 32, 2).image
        np.testing.assert_allclose(images[i], np.round(np.clip(alone, 0, 1) * 255) / 255, atol=1.5 / 255)
        assert np.abs(images[i] - np.round(np.clip(alone, 0, 1) * 255) / 255).mean() < 1e-3


@pytest.mark.parametrize("tol", list(TOLERANCES.values()) + [Tolerance("ratio", 0.5, 3.0)])
def test_distance_is_within_one_exactly_where_the_tolerance_holds(tol):
    rng = np.random.default_rng(0)
    for reference in (0.3, 5.0, 40.0):
        for other in reference * np.exp(rng.normal(0, 0.6, 200)):
            assert (tol.distance(reference, other) <= 1) == tol.holds(reference, other), (tol, reference, other)
    assert tol.distance(1.0, math.nan) == math.inf
    if tol.kind == "ratio":  # real chips without a gain swing (median 0) are matched by renders without one
        assert tol.distance(0.0, 0.0) == 0 and tol.holds(0.0, 0.0)
        assert tol.distance(0.0, 0.02) == math.inf and not tol.holds(0.0, 0.02) and not tol.holds(0.02, 0.0)


def test_ratio_distance_counts_half_and_double_alike():
    tol = Tolerance("ratio", 0.5, 2.0)
    assert tol.distance(10, 20) == pytest.approx(1.0) and tol.distance(10, 5) == pytest.approx(1.0)
    assert tol.distance(10, 40) == pytest.approx(2.0)


PRESET = """
[sonar]
max_range = 60.0
near_range = 30.0
chip_size = 12.0
[seafloor]
albedo = 0.5
rms_height = 0.01
[[targets]]
shape = "cylinder"
x = {uniform = [-1.5, 0.0]}
yaw = {uniform = [0.0, 180.0]}
length = 2.0
radius = 0.4
[post]
gain = GAIN
speckle_looks = 4.0
noise_std = 0.01
"""


def test_the_corrected_phi_distance_does_not_reward_renders_drawn_in_towards_their_mean():
    """32 draws of a 256-dimensional Gaussian whose variance falls as 1 / k (as φ's does) against 115 others: the
    plain FID scores them narrowed to 0.8 or 0.6 of their spread well below themselves, the corrected one not, and
    both still charge a wider spread."""
    from sasmi.eval.metrics import fid

    rng = np.random.default_rng(0)
    scale = np.arange(1, 257) ** -0.5

    def draw(n: int) -> np.ndarray:
        return rng.standard_normal((n, len(scale))) * scale

    phi = draw(115)
    real = phi_references(phi, 32, seed=0)
    renders = [draw(32) for _ in range(30)]
    plain = {f: np.mean([fid(f * x, phi) for x in renders]) / real["phi_reference"] for f in (1, 0.8, 0.6, 1.25)}
    corrected = {f: np.mean([spread_corrected_fid(f * x, phi, real["phi_halves"]) for x in renders])
                 / real["phi_reference"] for f in (1, 0.8, 0.6, 1.25)}
    assert plain[0.8] < 0.9 * plain[1] and plain[0.6] < 0.9 * plain[1], plain
    assert corrected[0.8] > corrected[1] - 0.03 and corrected[0.6] > corrected[1] - 0.03, corrected
    assert corrected[1.25] > corrected[1] + 0.05, corrected


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    """Real chips made by a known preset (gain 0.3, seed 5), and a start preset at 2.5 x that gain."""
    root = tmp_path_factory.mktemp("calibrate")
    truth = Preset.from_dict(tomllib.loads(PRESET.replace("GAIN", "0.3")))
    images = render_chips(truth, 40, CalibrateConfig(size=64), seed=5)
    real = root / "real"
    real.mkdir()
    for i, image in enumerate(images):
        Image.fromarray(np.round(image * 255).astype(np.uint8)).save(real / f"{i:03d}.png")
    start = root / "start.toml"
    start.write_text(PRESET.replace("GAIN", "0.75"))
    return real, start


def test_the_variety_term_charges_renders_alike_and_spares_renders_as_varied_as_the_real_chips(known):
    """New draws of the preset that made the real chips cost little; one draw repeated costs nearly the whole
    weight (no real chip lies near it), on top of what the φ-FID ratio says."""
    from sasmi.eval.features import as_encoder

    real_folder, _ = known
    cfg = CalibrateConfig(chips=16, size=64)
    encoder = as_encoder(None)
    real = real_chips(real_folder, encoder, cfg.chips, cfg.size, cfg.seed)
    assert 0.3 < real.recall_reference < 1.0
    truth = Preset.from_dict(tomllib.loads(PRESET.replace("GAIN", "0.3")))
    varied = render_chips(truth, 16, cfg, seed=9)
    alike = np.repeat(varied[:1], 16, axis=0)
    charge = {name: score(images, real, encoder, Weights(variety=1.0))["objective"]
              - score(images, real, encoder)["objective"]
              for name, images in (("varied", varied), ("alike", alike))}
    assert charge["alike"] > 0.8 and charge["varied"] < 0.4, charge
    assert score(alike, real, encoder)["recall"] < 0.2


def distances_to_renders_of(truth: str, variants: dict[str, str], tmp_path, part: str | None = "distances",
                            weights: Weights = Weights()):
    """40 renders of preset text `truth` as the real chips; each variant's 24 renders of other scenes scored against
    them with `weights`: (the real chips, variant -> the score's `part`, by default the objective's tolerance
    distances; None: the whole score)."""
    from sasmi.eval.features import as_encoder

    cfg = CalibrateConfig(chips=24, size=64)
    real_folder = tmp_path / "real"
    real_folder.mkdir()
    for i, image in enumerate(render_chips(Preset.from_dict(tomllib.loads(truth)), 40, cfg, seed=5)):
        Image.fromarray(np.round(image * 255).astype(np.uint8)).save(real_folder / f"{i:03d}.png")
    encoder = as_encoder(None)
    real = real_chips(real_folder, encoder, cfg.chips, cfg.size, cfg.seed)
    scores = {name: score(render_chips(Preset.from_dict(tomllib.loads(text)), 24, cfg, seed=9), real, encoder,
                          weights) for name, text in variants.items()}
    return real, {name: s if part is None else s[part] for name, s in scores.items()}


def test_the_objective_charges_targets_off_their_place_a_missing_gain_swing_and_a_speckle_that_never_wanders(
        tmp_path):
    """Real chips with centred targets a metre nearer than the centre column, a gain swing and a speckle grainier in
    some patches: new draws of their preset match all four; the same preset with its targets spread ±2 m along track
    misses the offset along track alone, with its targets at the centre column the offset along range alone, without
    the swing the swing alone, and without the wander the wander alone."""
    truth = PRESET.replace("GAIN", "0.3").replace("x = {uniform = [-1.5, 0.0]}", "x = {uniform = [-1.1, -0.9]}") \
        + "gain_swing = 0.15\nspeckle_wander = 0.3\n"
    variants = {"truth": truth, "off_centre": truth.replace('shape = "cylinder"', 'shape = "cylinder"\ny = {uniform = '
                                                                                  '[-2.0, 2.0]}'),
                "at_centre": truth.replace("x = {uniform = [-1.1, -0.9]}", "x = {uniform = [-0.1, 0.1]}"),
                "no_swing": truth.replace("gain_swing = 0.15", "gain_swing = 0.0"),
                "no_wander": truth.replace("speckle_wander = 0.3", "speckle_wander = 0.0")}
    real, distances = distances_to_renders_of(truth, variants, tmp_path)
    parts = ("offset_track", "offset_range", "bands", "wander")
    assert set(parts) <= set(real.checked)
    for name, missed in (("truth", None), ("off_centre", "offset_track"), ("at_centre", "offset_range"),
                         ("no_swing", "bands"), ("no_wander", "wander")):
        for part in parts:
            assert (distances[name][part] > 1.5) if part == missed else (distances[name][part] <= 1), (name, distances)


def test_the_auc_tolerance_is_two_standard_errors_of_the_auc_of_one_distribution():
    """AUCs of 32 draws against 115 of one distribution spread by half the tolerance, and a shift of 0.7 standard
    deviations lies beyond it."""
    from scipy.stats import mannwhitneyu

    rng = np.random.default_rng(0)
    aucs = [mannwhitneyu(rng.standard_normal(32), rng.standard_normal(115)).statistic / (32 * 115)
            for _ in range(2000)]
    assert auc_tolerance(115, 32) == pytest.approx(2 * np.std(aucs), rel=0.05)
    shifted = np.mean([mannwhitneyu(rng.standard_normal(32) + 0.7, rng.standard_normal(115)).statistic / (32 * 115)
                       for _ in range(200)])
    assert shifted - 0.5 > auc_tolerance(115, 32), shifted


def test_the_report_s_two_sample_test_tells_other_chips_and_not_new_draws_of_the_same():
    """New draws of the preset that made the real chips are told near chance; the same draws a third darker, almost
    always."""
    truth = Preset.from_dict(tomllib.loads(PRESET.replace("GAIN", "0.3")))
    cfg = CalibrateConfig(size=64)
    real, same = render_chips(truth, 40, cfg, seed=5), render_chips(truth, 40, cfg, seed=9)
    near, darker = told_apart(real, same, seed=0)["auc"], told_apart(real, same * 0.65, seed=0)["auc"]
    assert near < 0.75 and darker > 0.9, (near, darker)


def test_the_distribution_term_charges_the_statistic_a_classifier_would_tell_the_renders_by(tmp_path):
    """Real chips with a gain swing: new draws of their preset lie on neither side of them by any statistic; the same
    preset without the swing lies below by its bands along track, brighter above by its gray level, with targets
    twice as long above by their sizes (yawed at random, they lengthen shadows along track and range), each several
    tolerances off 0.5."""
    truth = PRESET.replace("GAIN", "0.3") + "gain_swing = 0.15\n"
    variants = {"truth": truth, "no_swing": truth.replace("gain_swing = 0.15", "gain_swing = 0.0"),
                "brighter": truth.replace("gain = 0.3", "gain = 0.6"),
                "longer": truth.replace("length = 2.0", "length = 4.0")}
    _, scores = distances_to_renders_of(truth, variants, tmp_path, part=None, weights=Weights(distribution=1.0))
    aucs, terms = ({n: s[part] for n, s in scores.items()} for part in ("aucs", "distribution"))
    tolerance = auc_tolerance(40, 24)
    assert all(abs(a - 0.5) <= 1.5 * tolerance for a in aucs["truth"].values()), aucs["truth"]
    assert aucs["no_swing"]["bands along track"] < 0.5 - 2 * tolerance, aucs["no_swing"]
    assert aucs["brighter"]["level"] > 0.5 + 2 * tolerance, aucs["brighter"]
    assert max(aucs["longer"][k] for k in MASK_STATISTICS) > 0.5 + 2 * tolerance, aucs["longer"]
    assert terms["truth"] < 1 < min(terms["no_swing"], terms["brighter"], terms["longer"]), terms


def test_the_distribution_weight_adds_the_distribution_term_to_the_objective(known):
    """Off by default (not computed); with --distribution-weight W the objective rises by W times the term, and
    renders all alike (one draw repeated) carry a larger term than new draws of the real chips' preset."""
    from sasmi.eval.features import as_encoder

    real_folder, _ = known
    cfg = CalibrateConfig(chips=16, size=64)
    encoder = as_encoder(None)
    real = real_chips(real_folder, encoder, cfg.chips, cfg.size, cfg.seed)
    varied = render_chips(Preset.from_dict(tomllib.loads(PRESET.replace("GAIN", "0.3"))), 16, cfg, seed=9)
    terms = {}
    for name, images in (("varied", varied), ("alike", np.repeat(varied[:1], 16, axis=0))):
        plain, once = score(images, real, encoder), score(images, real, encoder, Weights(distribution=1.0))
        twice = score(images, real, encoder, Weights(distribution=2.0))
        assert plain["distribution"] is None and plain["aucs"] == {}, name
        assert once["objective"] - plain["objective"] == pytest.approx(once["distribution"]), name
        assert twice["objective"] - plain["objective"] == pytest.approx(2 * once["distribution"]), name
        terms[name] = once["distribution"]
    assert CalibrateConfig().weights().distribution == 0
    assert terms["alike"] > 2 * terms["varied"], terms


def test_on_floor_chips_the_objective_charges_targets_found_and_ignores_their_sizes(tmp_path):
    """Real floor chips without a target: a target's sizes are not matched, but renders that show one where the real
    floors show none (ripple crests and rocks read as targets) miss the share of chips with a target."""
    with_target = PRESET.replace("GAIN", "0.3")
    floor = with_target.split("[[targets]]")[0] + "[post]" + with_target.split("[post]")[1]
    real, distances = distances_to_renders_of(floor, {"floor": floor, "target": with_target}, tmp_path)
    assert "targets_found" in real.checked and not {"shadow_length", "offset_track"} & set(real.checked)
    assert distances["floor"]["targets_found"] <= 1, distances["floor"]
    assert distances["target"]["targets_found"] > 2, distances["target"]


def test_on_floor_chips_the_objective_charges_a_seabed_fainter_than_the_real_one(tmp_path):
    """Real floors of two sediments, one a third as strong as the other: renders of one sediment miss the seabed's
    contrast by several tolerances; new draws of the real floors' preset match it."""
    with_target = PRESET.replace("GAIN", "0.3")
    floor = with_target.split("[[targets]]")[0] + "[post]" + with_target.split("[post]")[1]
    sediments = floor.replace("rms_height = 0.01", "rms_height = 0.01\nmosaic_contrast = 0.33\nmosaic_size = 6.0")
    real, distances = distances_to_renders_of(sediments, {"truth": sediments, "one": floor}, tmp_path)
    assert "seabed" in real.checked
    assert distances["truth"]["seabed"] <= 1 and distances["one"]["seabed"] > 3, (distances["truth"], distances["one"])


@pytest.mark.parametrize("share, real, renders", [(0.83, 115, 32), (0.5, 40, 16), (0.1, 60, 32)])
def test_the_share_of_chips_with_a_target_is_held_to_two_standard_errors_of_its_draws(share, real, renders):
    """Real chips and a trial's renders drawn alike: their shares of chips with a target found fall within the tolerance
    about 95 % of the time, as two standard errors should, at the MILCO targets' share and elsewhere."""
    rng = np.random.default_rng(0)
    tol = found_tolerance(share, real, renders)
    real_shares, trial_shares = rng.binomial(real, share, 20000) / real, rng.binomial(renders, share, 20000) / renders
    inside = np.mean([tol.distance(r, t) <= 1 for r, t in zip(real_shares, trial_shares)])
    assert 0.92 <= inside <= 0.985, (tol.high, inside)


def test_on_floors_where_no_target_is_found_one_render_in_16_with_one_passes_by_chance_and_two_do_not():
    tol = found_tolerance(0.0, 42, 16)
    assert tol.distance(0.0, 1 / 16) <= 1 < tol.distance(0.0, 2 / 16) and tol.distance(0.0, 3 / 16) > 2


def test_calibrate_recovers_a_known_gain_and_continues_when_rerun(known, tmp_path, quick_two_sample):
    real, start = known
    cfg = CalibrateConfig(params=("post.gain",), trials=25, chips=16, size=64, final_chips=16, searches=1)
    out = calibrate(real, start, cfg, tmp_path / "run", progress=False)
    fitted = load_preset(out / "preset.toml")
    assert fitted.raw["post"]["gain"] == pytest.approx(0.3, rel=0.15)
    report = (out / "report.md").read_text()
    assert "post.gain: 0.75 ->" in (out / "preset.toml").read_text()
    assert "25 trials" in report and (out / "sheet.png").is_file() and (out / "objective.png").is_file()
    assert "Precision / recall in φ" in report
    told = re.search(r"two-sample test .*: start (\d\.\d\d) ± \d\.\d\d, calibrated (\d\.\d\d) ± ", report)
    assert told and all(0 <= float(a) <= 1 for a in told.groups()), report
    assert "How well each statistic alone tells the renders" in report and "| bands along track (" in report
    assert not (out / "ridges.png").exists() and "ridges.png" not in report  # one knob: no pair moves together
    assert json.loads((out / "together.json").read_text()) == {} and "What the chips pin together" not in report
    pins = json.loads((out / "sensitivity.json").read_text())["post.gain"]
    # the gain moves the objective alone, and the best trials 15 % below and above it score worse on other draws
    assert "| post.gain | 0.3" in report and pins["alone"] and pins["pinned"] is True
    assert all(side["rise"] >= 0.1 for side in pins["beyond"].values()) and len(pins["fresh"]) == 4

    import optuna

    study = optuna.load_study(study_name="calibrate", storage=f"sqlite:///{out / 'study.db'}")
    first = [t.params for t in study.trials]
    assert first[0] == {"post.gain": 0.75}  # trial 0: the start preset
    calibrate(real, start, CalibrateConfig(**{**cfg.__dict__, "trials": 30}), out, progress=False)
    study = optuna.load_study(study_name="calibrate", storage=f"sqlite:///{out / 'study.db'}")
    assert len(study.trials) == 30 and [t.params for t in study.trials[:25]] == first

    # 20 renders a trial: more noise in their share of chips with a target, so a wider tolerance on it
    with pytest.raises(SasmiError, match="other settings \\(chips, found_tolerance\\)"):
        calibrate(real, start, CalibrateConfig(**{**cfg.__dict__, "chips": 20}), out, progress=False)
    # a study whose objective matched other statistics (another sasmi's) is not continued under this one's
    kept = (out / "calibrate.json").read_text()
    record = json.loads(kept)
    assert "offset_track" in record["identity"]["statistics"]
    record["identity"]["statistics"].remove("offset_track")
    (out / "calibrate.json").write_text(json.dumps(record))
    with pytest.raises(SasmiError, match="other settings \\(statistics\\)"):
        calibrate(real, start, CalibrateConfig(**{**cfg.__dict__, "trials": 30}), out, progress=False)
    (out / "calibrate.json").write_text(kept)
    # the φ and distribution terms are part of what a rerun must share: named among the settings that differ
    refused = {}
    for flag in ([], ["--plain-fid"], ["--distribution-weight", "1"]):
        done = subprocess.run([sys.executable, "-m", "sasmi", "calibrate", "--real", str(real), "--preset", str(start),
                               "--params", "post.gain", "--chips", "16", "--size", "64", "--out", str(out), *flag],
                              capture_output=True, text=True)
        assert done.returncode == 2, done.stderr
        refused[tuple(flag)] = done.stderr
    assert "spread_correction" in refused[("--plain-fid",)] and "spread_correction" not in refused[()], refused
    assert "distribution_weight" in refused[("--distribution-weight", "1")], refused


def test_a_calibration_killed_inside_a_trial_resumes_exactly(known, tmp_path, monkeypatch, quick_two_sample):
    """Killed while a trial of CMA-ES's second generation renders, the rerun scores that trial as it was asked and
    asks what an unbroken run asks: every trial's knobs and score alike, in each of two searches."""
    import optuna

    import sasmi.realism.calibrate as calibrate_module

    class Killed(BaseException):
        pass

    real, start = known
    cfg = CalibrateConfig(params=("post.gain",), trials=16, chips=8, size=64, final_chips=8, searches=2)
    whole = calibrate(real, start, cfg, tmp_path / "whole", progress=False)
    scored, calls = calibrate_module.trial_score, []

    def dies_at_the_eleventh(*args):  # the searches take turns, 8 trials each: search 0's 6th trial
        calls.append(1)
        if len(calls) == 11:
            raise Killed  # as kill -9: nothing told, the trial left asked
        return scored(*args)

    monkeypatch.setattr(calibrate_module, "trial_score", dies_at_the_eleventh)
    with pytest.raises(Killed):
        calibrate(real, start, cfg, tmp_path / "cut", progress=False)
    monkeypatch.setattr(calibrate_module, "trial_score", scored)
    calibrate(real, start, cfg, tmp_path / "cut", progress=False)

    def trials(out):
        return [[(t.state, t.params, t.value) for t in
                 optuna.load_study(study_name=name, storage=f"sqlite:///{out / 'study.db'}").trials]
                for name in ("calibrate", "calibrate-1")]

    assert trials(tmp_path / "cut") == trials(whole) and list(map(len, trials(whole))) == [8, 8]
    assert (tmp_path / "cut" / "preset.toml").read_text() == (whole / "preset.toml").read_text()


def test_gradient_refinement_is_kept_only_where_it_lowers_the_objective(known, tmp_path, monkeypatch,
                                                                        quick_two_sample):
    """One trial leaves the start's gain (2.5 x the truth's); a refinement that darkens the floor by that much is
    kept and written, one that brightens it further is not. Then fit-scene itself, one step, end to end."""
    import sasmi.realism.fit_scene as fit_scene_module
    from sasmi.realism.fit_scene import FitResult

    real, start = known
    cfg = CalibrateConfig(params=("post.gain",), trials=1, chips=16, size=64, final_chips=16, refine_steps=3)
    for factor, kept in ((0.4, True), (2.5, False)):
        scales = {"seafloor.roughness": 1.0, "seafloor.albedo": factor, "sonar.elevation": 1.0}
        monkeypatch.setattr(fit_scene_module, "fit_scene", lambda *a, **k: FitResult(tuple(scales), scales, [], 0.0))
        out = calibrate(real, start, cfg, tmp_path / f"x{factor}", progress=False)
        report, albedo = (out / "report.md").read_text(), load_preset(out / "preset.toml").raw["seafloor"]["albedo"]
        assert "Gradient refinement, 3 steps" in report and ("kept (the calibrated column" in report) == kept
        assert albedo == pytest.approx(0.5 * factor if kept else 0.5)
    monkeypatch.undo()
    out = calibrate(real, start, replace(cfg, refine_steps=1), tmp_path / "x0.4", progress=False)  # its search done
    assert "Gradient refinement, 1 steps" in (out / "report.md").read_text()


def test_cli_refuses_bad_input_in_one_line(known, tmp_path):
    real, start = known
    for args, words in ((["--params", "post.gian"], "unknown parameter post.gian"),
                        (["--chips", "4"], "--chips: 4"), (["--final-chips", "7"], "--final-chips: 7"),
                        (["--variety-weight", "-1"], "--variety-weight"),
                        (["--contenders", "0"], "--contenders"), (["--profile-trials", "-1"], "--profile-trials"),
                        (["--preset", str(tmp_path / "none.toml")], "not found"),
                        (["--params", "seafloor[0].albedo"], "one [seafloor] table")):
        done = subprocess.run([sys.executable, "-m", "sasmi", "calibrate", "--real", str(real), "--out",
                               str(tmp_path / "run"), *args], capture_output=True, text=True)
        assert done.returncode == 2 and words in done.stderr and "Traceback" not in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run" / "study.db").exists()


def test_a_full_disk_under_the_study_is_one_line(known, tmp_path, monkeypatch):
    import optuna
    import sqlalchemy.exc

    def full(*args, **kwargs):
        raise sqlalchemy.exc.OperationalError("INSERT", {}, Exception("database or disk is full"))

    real, start = known
    monkeypatch.setattr(optuna.study.Study, "tell", full)
    with pytest.raises(SasmiError, match="study.db: cannot write \\(the disk is full\\); free some space"):
        calibrate(real, start, CalibrateConfig(params=("post.gain",), trials=3, chips=16, size=64), tmp_path / "run",
                  progress=False)


def test_trials_scored_on_dask_workers_score_as_here(known, tmp_path, quick_two_sample):
    """--workers 2: trials scored side by side on a local Dask cluster, each worker with its own φ and share
    of the cores; the start preset's trial scores as it does here."""
    import optuna

    real, start = known
    scores = {}
    for workers in (1, 2):
        cfg = CalibrateConfig(params=("post.gain",), trials=4, chips=16, size=64, final_chips=16, workers=workers)
        out = calibrate(real, start, cfg, tmp_path / f"run{workers}", progress=False)
        study = optuna.load_study(study_name="calibrate", storage=f"sqlite:///{out / 'study.db'}")
        assert len(study.trials) == 4 and all(t.value is not None for t in study.trials)
        scores[workers] = study.trials[0].value
    assert scores[2] == pytest.approx(scores[1], rel=1e-6)

    # the knob moves of the report were scored on the workers too, as here
    from sasmi.eval.features import as_encoder
    from sasmi.realism.calibrate import apply, trial_score
    from sasmi.realism.calibration_pins import sensitivity

    preset, encoder = load_preset(start), as_encoder(None)
    chips = real_chips(real, encoder, cfg.chips, cfg.size, cfg.seed)
    best = study.trials[study.user_attrs["calibrated_trial"]].params
    here = sensitivity(best, lambda settings: [trial_score(apply(preset.raw, v), preset.path, chips, cfg,
                                                           encoder)["objective"] for v in settings])
    there = json.loads((out / "sensitivity.json").read_text())
    assert there["post.gain"]["rise"] == pytest.approx(here["post.gain"]["rise"], rel=1e-6)


def test_the_calibrated_trial_is_the_contender_scoring_best_on_other_draws(known):
    """The search's best (gain 0.5) owes its lead to its own scenes' draw: of the 8 best trials, the one
    scoring lowest on other draws (gain 0.3) is calibrated; the tenth best, better still, is not a contender."""
    import optuna

    from sasmi.realism.calibration_study import calibrated_trial

    _, start = known
    preset = load_preset(start)
    cfg = CalibrateConfig(params=("post.gain",), chips=16, size=64, final_chips=16)
    study = optuna.create_study()
    gains = [0.5, 0.3, 0.45, 0.55, 0.6, 0.4, 0.65, 0.7, 0.8, 0.31]
    for rank, gain in enumerate(gains):
        study.add_trial(optuna.trial.create_trial(params={"post.gain": gain}, value=0.1 * (rank + 1),
                                                  distributions={"post.gain": optuna.distributions.FloatDistribution(
                                                      0.01, 2.0, log=True)}))
    calls = []

    def objectives_of(settings, seed):
        calls.append(seed)
        return [abs(math.log(v["post.gain"] / 0.3)) + 0.01 * seed for v in settings]

    raw, trial = calibrated_trial(study, preset, cfg, replace(cfg, seed=1), objectives_of, [2, 3, 4])
    assert trial.params["post.gain"] == 0.3 and raw["post"]["gain"] == 0.3 and calls == [2, 3, 4]
    assert study.user_attrs["calibrated_trial"] == 1
    scores = study.user_attrs["contenders"]["scores"]
    assert len(scores) == cfg.contenders == 8 and [s[0] for s in scores] == list(range(8))
    assert scores[1][2] == pytest.approx(0.03) and study.user_attrs["contenders"]["draws"] == 3
    # one contender: the search's best, as it scored on its own scenes
    _, trial = calibrated_trial(study, preset, replace(cfg, contenders=1), replace(cfg, seed=1), objectives_of, [2])
    assert trial.number == 0
