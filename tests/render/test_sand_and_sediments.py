"""Seabed options beyond a rough, rippled floor: sinuous ripple crests and two sediments (docs/physics.md)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.signal import hilbert

from sasmi.render.post import post_fields
from sasmi.render.seafloor import surface
from sasmi.scene.model import Post, Scene, Seafloor, Sonar

SIZE = 128
CHIP = 6.0  # m


def texture(seed: int, post: Post = Post(speckle_looks=0.0, noise_std=0.0), **floor) -> np.ndarray:
    """(SIZE, SIZE) echo map of a flat floor: the mosaic alone when the speckle is off."""
    scene = Scene(sonar=Sonar(near_range=35.0, chip_size=CHIP), seafloor=Seafloor(rms_height=0.0, **floor),
                  post=post, seed=seed).validate()
    return post_fields(scene, SIZE)[0]


def boundary_density(second: np.ndarray) -> float:
    """Share of neighbouring pixel pairs (along either axis) that lie on two sediments."""
    return float(np.mean(second[1:] != second[:-1]) + np.mean(second[:, 1:] != second[:, :-1])) / 2


def test_a_second_sediment_covers_its_share_in_patches_with_sharp_boundaries():
    """mosaic_contrast 3, share 0.3: each chip takes two levels 3 apart and nothing between; over chips the second
    covers 0.3 and the level's mean stays 1; patches larger than the chip leave some chips one sediment and cross
    others; four times larger patches draw about four times fewer boundaries."""
    floor = dict(mosaic_contrast=3.0, mosaic_share=0.3)
    large = [texture(seed, mosaic_size=2 * CHIP, **floor) for seed in range(60)]
    for t in large[:10]:
        levels = np.unique(t)
        assert len(levels) <= 2 and (len(levels) == 1 or levels[1] / levels[0] == pytest.approx(3.0))
    high = 3.0 / (0.7 + 0.3 * 3.0)
    shares = np.array([np.isclose(t, high).mean() for t in large])
    assert shares.mean() == pytest.approx(0.3, abs=0.07) and np.mean(large) == pytest.approx(1.0, abs=0.06)
    single = np.mean((shares == 0) | (shares == 1))
    assert 0.25 < single < 0.9, single
    small = [boundary_density(texture(seed, mosaic_size=CHIP / 8, **floor) > 1) for seed in range(20)]
    middle = [boundary_density(texture(seed, mosaic_size=CHIP / 2, **floor) > 1) for seed in range(20)]
    assert 2.5 < np.mean(small) / np.mean(middle) < 6, (np.mean(small), np.mean(middle))


def test_the_mosaic_multiplies_the_speckle_from_its_own_stream():
    speckled = Post(speckle_looks=4.0, noise_std=0.0)
    plain = texture(3, post=speckled)
    np.testing.assert_array_equal(plain, texture(3, post=speckled, mosaic_size=CHIP / 3, mosaic_share=0.5))
    mosaic = texture(3, mosaic_contrast=0.25, mosaic_size=CHIP / 3, mosaic_share=0.5)
    np.testing.assert_allclose(texture(3, post=speckled, mosaic_contrast=0.25, mosaic_size=CHIP / 3,
                                       mosaic_share=0.5), plain * mosaic)


def crest_wander(sinuosity: float, seed: int) -> float:
    """sd over the chip of the crests' sideways offset from straight ones, in wavelengths: the phase of each row's
    ripple (analytic signal along range) less a straight ripple's."""
    wavelength = CHIP / 8
    floor = Seafloor(rms_height=0.0, ripple_amplitude=0.02, ripple_wavelength=wavelength, ripple_direction=0.0,
                     ripple_sinuosity=sinuosity)
    heights = surface(floor, CHIP, seed).grid(256)[:-1, :-1]
    x = np.linspace(-CHIP / 2, CHIP / 2, 257)[:-1]
    offset = np.exp(1j * (np.angle(hilbert(heights, axis=1)) - 2 * np.pi * x / wavelength))
    offset = offset[:, 16:-16]  # the analytic signal's ends see the row wrap
    residual = np.angle(offset * np.conj(offset.mean()))
    return float(residual.std() / (2 * np.pi))


@pytest.mark.parametrize("sinuosity", [0.05, 0.1])
def test_sinuous_ripple_crests_wander_sideways_by_their_sinuosity(sinuosity):
    wander = np.mean([crest_wander(sinuosity, seed) for seed in range(6)])
    assert wander == pytest.approx(sinuosity, rel=0.1)
    assert crest_wander(0.0, 0) < 0.005


def test_sinuosity_leaves_the_rough_surface_and_the_rocks_as_they_were():
    floor = Seafloor(rms_height=0.01, ripple_amplitude=0.02, rocks=4)
    straight, sinuous = surface(floor, CHIP, 2), surface(dataclasses.replace(floor, ripple_sinuosity=0.2), CHIP, 2)
    np.testing.assert_array_equal(straight.rough, sinuous.rough)
    assert straight.rocks == sinuous.rocks and straight.ripple_phase == sinuous.ripple_phase
    assert not np.allclose(straight.grid(64), sinuous.grid(64))


@pytest.mark.parametrize("sharpness", [1.0, 3.0, 8.0])
def test_sharp_ripples_narrow_their_crests_and_keep_their_height_and_mean_level(sharpness):
    # crests above half the crest-to-trough height over acos(2 x 0.5^(1/sharpness) - 1) / pi of a wavelength:
    # half for the sinusoid, 0.30 at 3, 0.19 at 8
    floor = Seafloor(rms_height=0.0, ripple_amplitude=0.05, ripple_wavelength=CHIP / 8, ripple_direction=0.0,
                     ripple_sharpness=sharpness)
    heights = surface(floor, CHIP, 3).grid(256)[:-1, :-1]
    crest, trough = heights.max(), heights.min()
    assert crest == pytest.approx(0.05, rel=0.01)  # 32 samples a wavelength straddle the crest
    assert abs(heights.mean()) < 1e-4
    share = np.mean(heights > (crest + trough) / 2)
    assert share == pytest.approx(np.arccos(2 * 0.5 ** (1 / sharpness) - 1) / np.pi, abs=0.02)
