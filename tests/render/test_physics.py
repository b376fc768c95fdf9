"""The sonar physics options, one test each that fails when the option is ignored (docs/physics.md)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sasmi.render.mitsuba import Renderer
from sasmi.errors import SasmiError
from sasmi.render.annotate import MASK_SHADOW
from sasmi.render.seafloor import rocks, surface
from sasmi.scene.model import Post, Scene, Seafloor, Sonar, Target

QUIET = Post(speckle_looks=0.0, noise_std=0.0)


def rough_floor(seed: int = 1, **post) -> Scene:
    return Scene(sonar=Sonar(near_range=35.0),
                 seafloor=Seafloor(rms_height=0.02, correlation_length=0.3, ripple_amplitude=0.01,
                                   ripple_wavelength=0.8, ripple_direction=30.0, rocks=5),
                 post=dataclasses.replace(QUIET, **post), seed=seed).validate()


@pytest.mark.parametrize("seed", [1, 2])
def test_the_seafloor_is_the_same_at_every_size(seed):
    """A 256 px render block-averaged to 64 px shows the 64 px render's floor.

    The floor is defined in metres, not per pixel grid, so both sizes show one floor; a floor
    drawn per pixel grid would give two unrelated ones. What differences remain are the coarser
    mesh's shading of relief finer than a 64 px cell (rocks, 0.3 m roughness).
    """
    scene = rough_floor(seed)
    fine = Renderer(256, 16).render(scene).image.astype(np.float64)
    coarse = Renderer(64, 64).render(scene).image.astype(np.float64)
    block = fine.reshape(64, 4, 64, 4).mean(axis=(1, 3))
    r = np.corrcoef(block.ravel(), coarse.ravel())[0, 1]
    relative = np.abs(block - coarse).mean() / coarse.mean()
    assert r > 0.9 and relative < 0.25, (r, relative)
    assert abs(block.mean() / coarse.mean() - 1) < 0.03


@pytest.mark.parametrize("floor", [rough_floor().seafloor, Seafloor(rms_height=0.0, rocks=3)])
def test_the_rocks_drawn_for_a_label_are_the_rendered_floors(floor):
    """A render labels the rocks of the floor it built; a label made without the floor draws them alone."""
    assert len(surface(floor, 20.0, 7).rocks) == floor.rocks
    assert rocks(floor, 20.0, 7) == surface(floor, 20.0, 7).rocks


# -- sonar physics options: each test fails when its option is ignored -----------------

@pytest.fixture(scope="module")
def renderer64() -> Renderer:
    return Renderer(64, 32)


def flat_chip(sonar: Sonar = Sonar(near_range=35.0), post: Post = QUIET, seafloor: Seafloor = Seafloor(rms_height=0.0),
              targets: tuple = (Target(x=-0.5, yaw=30.0),)) -> Scene:
    return Scene(sonar=sonar, seafloor=seafloor, post=post, targets=targets, seed=5).validate()


def far_over_near(image: np.ndarray) -> float:
    third = image.shape[1] // 3  # columns are ground range
    return float(image[:, -third:].mean() / image[:, :third].mean())


def test_altitude_is_its_own_field(renderer64):
    """sonar.altitude moves the array without moving max_range; 0 keeps the paper's max_range / 10."""
    from sasmi.render.geometry import emitter_positions

    paper, high = flat_chip(), flat_chip(sonar=Sonar(near_range=35.0, altitude=12.0))
    assert paper.sonar.max_range == high.sonar.max_range and paper.sonar.array_altitude == 6.0
    np.testing.assert_allclose(emitter_positions(high)[:, 2] * high.sonar.chip_size / 2, 12.0)
    shadow = {name: (renderer64.render(s).mask == MASK_SHADOW).sum() for name, s in (("paper", paper), ("high", high))}
    # twice the altitude, twice the grazing angle: the shadow is about half as long
    assert shadow["high"] < 0.7 * shadow["paper"], shadow


def test_partial_tvg_leaves_a_range_fall_off(renderer64):
    """tvg_strength 1 evens out a flat floor, 0 is no TVG, 0.5 in between (in far / near brightness)."""
    ratio = {st: far_over_near(renderer64.render(flat_chip(post=dataclasses.replace(QUIET, tvg_strength=st),
                                                           targets=())).image) for st in (1.0, 0.5, 0.0)}
    untouched = far_over_near(renderer64.render(flat_chip(post=dataclasses.replace(QUIET, tvg=False), targets=())).image)
    assert abs(ratio[1.0] - 1) < 0.02 and ratio[0.0] == pytest.approx(untouched, abs=1e-3)
    assert ratio[0.0] + 0.05 < ratio[0.5] < ratio[1.0] - 0.05, ratio


def test_noise_floor_lifts_shadows(renderer64):
    """post.noise_floor is added under every echo: shadows sit at that level instead of black."""
    level = 0.04
    dark = renderer64.render(flat_chip())
    lifted = renderer64.render(flat_chip(post=dataclasses.replace(QUIET, noise_floor=level)))
    shadow = dark.mask == MASK_SHADOW
    assert shadow.sum() > 50 and np.percentile(dark.image[shadow], 10) < 0.01
    unclipped = lifted.image < 1
    np.testing.assert_allclose((lifted.image - dark.image)[unclipped], level, atol=1e-5)
    # with speckle the floor is speckled too: its mean stays the level
    speckled = renderer64.render(flat_chip(post=dataclasses.replace(QUIET, noise_floor=level, speckle_looks=4.0)))
    assert speckled.image[shadow].std() > 0.01


def autocorrelation(field: np.ndarray, axis: int) -> float:
    a = field - field.mean()
    return float((a * np.roll(a, 1, axis=axis)).mean() / a.var())


def test_speckle_cell_correlates_speckle_over_the_resolution_cell():
    """speckle_cell_range / _track (m): neighbouring pixels within a cell share their speckle; the
    marginal stays L-look gamma (mean 1, variance 1 / L)."""
    from sasmi.render.post import post_fields

    size, looks = 128, 4.0
    pixel = 6.0 / size
    plain = flat_chip(post=Post(speckle_looks=looks), targets=())
    cells = flat_chip(post=Post(speckle_looks=looks, speckle_cell_range=4 * pixel, speckle_cell_track=1.5 * pixel),
                      targets=())
    independent, _ = post_fields(plain, size)
    correlated, _ = post_fields(cells, size)
    assert abs(autocorrelation(independent, axis=1)) < 0.05 and abs(autocorrelation(independent, axis=0)) < 0.05
    along_range, along_track = autocorrelation(correlated, axis=1), autocorrelation(correlated, axis=0)
    assert along_range > 0.6 and 0.15 < along_track < along_range - 0.2, (along_range, along_track)
    assert correlated.mean() == pytest.approx(1, abs=0.03) and correlated.var() == pytest.approx(1 / looks, rel=0.15)


def test_patchiness_textures_the_floor_in_patches_of_patch_size():
    """seafloor.patchiness / patch_size: a gamma texture (std / mean = patchiness) multiplies the
    speckle, correlated over patches of patch_size; the noise floor under it stays untextured, and
    the texture draws from its own stream: without it the speckle is the same."""
    from sasmi.render.post import post_fields

    size = 128
    pixel = 6.0 / size
    post = Post(speckle_looks=0.0, noise_floor=0.02)

    def fields(**floor) -> tuple[np.ndarray, np.ndarray]:
        return post_fields(flat_chip(post=post, seafloor=Seafloor(**floor), targets=()), size)

    texture, offset = fields(patchiness=0.4, patch_size=6 * pixel)
    assert texture.mean() == pytest.approx(1, abs=0.05) and texture.std() == pytest.approx(0.4, rel=0.15)
    assert autocorrelation(texture, axis=0) > 0.8 and autocorrelation(texture, axis=1) > 0.8
    fine, _ = fields(patchiness=0.4, patch_size=1.5 * pixel)
    assert autocorrelation(fine, axis=1) < autocorrelation(texture, axis=1) - 0.2
    np.testing.assert_array_equal(offset, 0.02)
    speckled = dataclasses.replace(flat_chip(post=Post(speckle_looks=4.0), targets=()), seed=3)
    textured = dataclasses.replace(speckled, seafloor=Seafloor(patchiness=0.3))
    np.testing.assert_array_equal(post_fields(speckled, size)[0], post_fields(
        dataclasses.replace(textured, seafloor=Seafloor(patchiness=0.0)), size)[0])
    assert post_fields(textured, size)[0].var() > 1.2 * post_fields(speckled, size)[0].var()


def speckled_floor(**post) -> Scene:
    """A flat floor with no target under 4-look speckle and a noise floor of 0.02, the `post` fields set beside."""
    return dataclasses.replace(flat_chip(post=Post(speckle_looks=4.0, noise_floor=0.02, **post), targets=()), seed=3)


def test_gain_swing_brightens_and_darkens_whole_rows_along_track():
    """post.gain_swing / gain_swing_length: each row along track times exp(gain_swing x n), n of unit sd
    correlated over gain_swing_length, from its own stream (the speckle under it is the same); the noise floor
    is spared; `sasmi stats` measures it as the gain swing along track."""
    from sasmi.chips.stats import gain_swing
    from sasmi.render.post import post_fields

    size = 128
    pixel = 6.0 / size
    plain, plain_offset = post_fields(speckled_floor(), size)
    banded, offset = post_fields(speckled_floor(gain_swing=0.1, gain_swing_length=3 * pixel), size)
    np.testing.assert_array_equal(offset, plain_offset)
    log_rows = np.log(banded / plain)
    np.testing.assert_allclose(log_rows, log_rows[:, :1] * np.ones((1, size)), atol=1e-12)  # whole rows
    rows = log_rows[:, 0]
    assert rows.std() == pytest.approx(0.1, rel=1e-6)
    lag = np.corrcoef(rows[:-3], rows[3:])[0, 1]  # exp(-3² / (4 · 3²)) = 0.78 for a Gaussian of sigma 3 px
    assert 0.6 < lag < 0.9, lag
    short = np.log(post_fields(speckled_floor(gain_swing=0.1, gain_swing_length=0.5 * pixel), size)[0] / plain)[:, 0]
    assert np.corrcoef(short[:-3], short[3:])[0, 1] < 0.2
    floor = np.ones((size, size), bool)
    assert gain_swing(0.3 * banded.clip(0, 3) / 3, floor) > gain_swing(0.3 * plain.clip(0, 3) / 3, floor) + 0.05


def test_speckle_wander_makes_the_speckle_grainier_in_some_patches_than_others():
    """post.speckle_wander / speckle_wander_length: the speckle's deviations from its mean times exp(w x field - w²),
    a field of unit sd smooth over speckle_wander_length, from its own stream (0: the speckle as it was); the noise
    floor's speckle wanders with it; `sasmi stats` reads it as the contrast's wander."""
    from sasmi.chips.floor_texture import contrast_wander
    from sasmi.render.post import post_fields

    size = 128
    pixel = 6.0 / size
    plain = post_fields(speckled_floor(), size)[0]
    np.testing.assert_array_equal(post_fields(speckled_floor(speckle_wander_length=8 * pixel), size)[0], plain)
    grainy, offset = post_fields(speckled_floor(speckle_wander=0.3, speckle_wander_length=8 * pixel), size)
    np.testing.assert_allclose(offset, 0.02 * grainy)
    assert grainy.mean() == pytest.approx(plain.mean(), rel=0.03)
    kept = (grainy > 0) & (np.abs(plain - plain.mean()) > 0.2)  # no clipping at 0, deviations far from 0
    log_scale = np.log((grainy - plain.mean())[kept] / (plain - plain.mean())[kept])
    assert log_scale.std() == pytest.approx(0.3, rel=0.1)
    scale = np.full((size, size), np.nan)
    scale[kept] = log_scale
    near = np.isfinite(scale[:, :-4]) & np.isfinite(scale[:, 4:])
    assert np.corrcoef(scale[:, :-4][near], scale[:, 4:][near])[0, 1] > 0.8  # smooth over 8 px
    floor = np.ones((size, size), bool)
    assert (contrast_wander(0.3 * grainy.clip(0, 3) / 3, floor, 8)
            > contrast_wander(0.3 * plain.clip(0, 3) / 3, floor, 8) + 0.1)


def test_lambert_squared_backscatter_sharpens_the_relief(renderer64):
    """seafloor.backscatter = lambert2 weighs each facet by cos^2(incidence): tilted facets stand out more
    (relief contrast std / mean); rough (cos^0.5) evens them out; a flat floor keeps its calibrated level
    under every law."""
    def chip(law: str, rms: float) -> np.ndarray:
        return renderer64.render(flat_chip(seafloor=Seafloor(rms_height=rms, correlation_length=0.3, backscatter=law),
                                           targets=())).image

    laws = ("lambert", "lambert2", "rough")
    contrast = {law: chip(law, 0.02).std() / chip(law, 0.02).mean() for law in laws}
    assert contrast["lambert2"] > 1.25 * contrast["lambert"] > 1.25 ** 2 * contrast["rough"], contrast
    for law in laws[1:]:
        assert chip(law, 0.0).mean() == pytest.approx(chip("lambert", 0.0).mean(), rel=0.02)


def test_rough_backscatter_keeps_a_targets_top_bright_at_low_grazing(renderer64):
    """A target's backscatter = rough (cos^0.5 of incidence) keeps its flat top, lit at 5° grazing, bright: under
    lambert the top fades as cos(incidence) = 0.08, under rough as its square root, 0.28. The block's mean
    brightens well over 2.5x (albedo 0.3 keeps it below saturation), while the floor, with its own law, stays put."""
    block = Target(shape="box", x=-0.5, yaw=0.0, length=1.5, width=1.5, height=0.4, albedo=0.3)  # flat top

    def chip(law: str):
        return renderer64.render(flat_chip(sonar=Sonar(near_range=35.0, altitude=3.0),
                                           targets=(dataclasses.replace(block, backscatter=law),)))

    lambert, rough = chip("lambert"), chip("rough")
    assert rough.image[rough.mask == 1].mean() > 2.5 * lambert.image[lambert.mask == 1].mean()
    np.testing.assert_array_equal(rough.mask, lambert.mask)
    assert rough.image[rough.mask == 0].mean() == pytest.approx(lambert.image[lambert.mask == 0].mean(), rel=0.01)


def test_slant_range_lays_a_tall_target_over_the_floor_in_front(renderer64):
    """sonar.slant_range: a 1.5 m cone under a steep (20 m altitude) array; its top is nearer in slant
    range than its base, so its highlight moves to the leading (near-range) edge, where the slant
    geometry puts it, far from the chip's middle column where ground range has it; a flat floor
    keeps its level."""
    from sasmi.render.geometry import build_geometry
    from sasmi.render.slant import slant_map

    def scene(slant: bool, targets=(Target(shape="cone", x=0.0, length=1.5, radius=0.5, radius_top=0.3),)) -> Scene:
        return flat_chip(sonar=Sonar(near_range=10.0, altitude=20.0, slant_range=slant), targets=targets)

    def brightest_column(image: np.ndarray) -> float:
        return float(np.unravel_index(np.argsort(image, axis=None)[-20:], image.shape)[1].mean())

    ground, slant = renderer64.render(scene(False)), renderer64.render(scene(True))
    top = float(slant_map(build_geometry(scene(True), 64), np.zeros((64, 64))).column(0.0, 1.5 * 2 / 6.0))
    assert abs(brightest_column(ground.image) - 31.5) < 3
    assert abs(brightest_column(slant.image) - top) < 3 and top < 15, (brightest_column(slant.image), top)
    c0, _, c1, _ = slant.labels["targets"][0]["bbox"]
    assert c0 <= brightest_column(slant.image) < c0 + 0.25 * (c1 - c0)  # the highlight leads the target
    flat = {s: renderer64.render(scene(s, targets=())).image for s in (False, True)}
    np.testing.assert_allclose(flat[True].mean(axis=0), flat[False].mean(axis=0), rtol=0.01)


def test_slant_range_moves_the_rock_boxes_with_the_rocks(renderer64):
    """sonar.slant_range squeezes the near range: the rocks' clutter boxes move with them, so the
    bright facets of the rocks stay inside (a box left at its ground-range columns misses them)."""
    scene = flat_chip(sonar=Sonar(near_range=10.0, altitude=20.0, slant_range=True), targets=(),
                      seafloor=Seafloor(rms_height=0.0, rocks=6, rock_radius=0.3))
    out = renderer64.render(scene)
    inside = np.zeros((64, 64), dtype=bool)
    for c in out.label.clutter:
        c0, r0, c1, r1 = c["bbox"]
        inside[r0:r1, c0:c1] = True
    bright = out.image > 1.3 * np.median(out.image)
    assert bright.sum() > 5 and inside[bright].all()
    assert [c["bbox"] for c in out.label.clutter] != [c["bbox"] for c in renderer64.render(
        flat_chip(sonar=Sonar(near_range=10.0, altitude=20.0), targets=(), seafloor=scene.seafloor)).label.clutter]


def test_aperture_grows_with_range():
    """sonar.aperture_angle: broadside beams, so the stretch of track that lights a point is 2 R tan(angle / 2):
    twice the range, twice the aperture (constant along-track resolution). With the paper's spots aimed at
    the chip centre every point sees the whole 20 m track."""
    from sasmi.render.geometry import beam_falloff, build_geometry

    def lit_track(aperture: float) -> tuple[float, float]:
        """m of track lighting the near-edge and the far-edge centre of a 20 m chip (30-50 m)."""
        scene = flat_chip(sonar=Sonar(near_range=30.0, chip_size=20.0, max_range=65.0, emitters=400,
                                      aperture_angle=aperture), targets=())
        g = build_geometry(scene, 16)
        points = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
        weights = beam_falloff(g.emitter_positions, g.aims, points, g.cone_angle, g.beam_width) \
            if g.broadside else np.ones((len(g.emitter_positions), 2))
        spacing = np.diff(g.emitter_positions[:, 1]).mean() * g.metres_per_unit
        return tuple(weights.sum(axis=0) * spacing)

    near, far = lit_track(20.0)
    ratio = np.hypot(50.0, 6.5) / np.hypot(30.0, 6.5)  # slant range far / near
    assert far / near == pytest.approx(ratio, rel=0.05), (near, far)
    # the profile is 1 out to 7.5 deg and falls linearly to 0 at 10 deg: about 2 R tan(8.75 deg) in all
    assert near == pytest.approx(2 * np.hypot(30.0, 6.5) * np.tan(np.radians(8.75)), rel=0.1)
    paper_near, paper_far = lit_track(0.0)
    assert paper_near == paper_far == pytest.approx(20.0, rel=0.01)
    with pytest.raises(SasmiError, match="sonar.aperture_angle: 4 deg beams do not cover the chip in elevation"):
        lit_track(4.0)


def test_aperture_keeps_a_flat_floor_even_and_darkens_shadows(renderer64):
    """With broadside beams the exposure and TVG follow the beam profile (a flat floor stays at its level
    across range); a narrower aperture than the paper's 20 m track fills a small target's shadow in less
    (a 0.3 m sphere at 6 deg)."""
    def scene(aperture: float, targets=()) -> Scene:
        return flat_chip(sonar=Sonar(near_range=35.0, aperture_angle=aperture), targets=targets)

    flat = renderer64.render(scene(6.0)).image
    columns = flat.mean(axis=0)
    assert abs(far_over_near(flat) - 1) < 0.04 and abs(columns.mean() / 0.225 - 1) < 0.03
    sphere = (Target(shape="sphere", x=-1.5, radius=0.3),)
    shadow = {a: (renderer64.render(scene(a, sphere)).mask == MASK_SHADOW).sum() for a in (0.0, 6.0)}
    assert shadow[6.0] > 1.25 * shadow[0.0], shadow


def test_too_narrow_aperture_fails_before_anything_is_written(tmp_path, capsys):
    from sasmi.cli.main import main

    preset = tmp_path / "narrow.toml"
    preset.write_text("[sonar]\naperture_angle = 2.0\n")
    out = tmp_path / "out"
    assert main(["render", str(preset), "--out", str(out), "--count", "1", "--size", "32"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sonar.aperture_angle: 2 deg" in err and "allowed: >=" in err
    assert not out.exists()


def test_speckle_table_lookup_is_np_interp():
    """The speckle's gamma quantiles are read by index arithmetic on their even grid: the same as np.interp."""
    from sasmi.render.post import _gamma_quantiles, _interp_uniform

    z, q = _gamma_quantiles(6.5)
    x = np.random.default_rng(3).normal(0.0, 3.0, (64, 64))
    x[0, :4] = [-20.0, 20.0, z[0], z[-1]]  # beyond the table and on its ends
    assert np.allclose(_interp_uniform(x, z, q), np.interp(x, z, q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("looks", [1.0, 6.5])
def test_speckle_table_is_within_a_fraction_of_a_gray_level_of_the_gamma_quantile(looks):
    """The tabulated quantile, interpolated, against scipy's Gamma(looks, 1 / looks) quantile itself."""
    from scipy import stats

    from sasmi.render.post import _gamma_quantiles, _interp_uniform

    z, q = _gamma_quantiles(looks)
    x = np.random.default_rng(4).normal(0.0, 1.5, 20000)
    exact = stats.gamma.ppf(stats.norm.cdf(x), looks, scale=1.0 / looks)
    assert np.abs(_interp_uniform(x, z, q) - exact).max() < 1e-4  # a gray level is 4e-3 of full scale
