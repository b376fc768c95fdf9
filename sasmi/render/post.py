"""The sonar's image formation after the render: time-varying gain, speckle, gain swings, noise floor, noise.

Radiance (H, W), exposure folded in, goes to a chip in [0, 1] as
    clip((radiance * gain * swing + noise_floor) * speckle + noise, 0, 1)
    = clip(radiance * gain * echo + offset, 0, 1),   echo = swing * speckle,   offset = noise_floor * speckle + noise
(the swing, a gain per row along track, is 1 when off; the speckle map `post_fields` returns is the echo's).
The maps are numpy and depend only on the scene, so `Renderer.render` computes them while
the Mitsuba kernel runs, and the differentiable render reuses the same speckle and offset.
docs/physics.md says what each models.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy import ndimage

from sasmi.render.geometry import Geometry, exposure, flat_floor_irradiance
from sasmi.render.sediments import mosaic
from sasmi.scene.model import Scene

Maps = tuple[np.ndarray, np.ndarray, np.ndarray]  # (H, W) float64 each: gain, speckle, offset
FWHM_PER_SIGMA = 2 * math.sqrt(2 * math.log(2))


def tvg_gain(positions: np.ndarray, size: int, cos_power: int = 1, strength: float = 1.0, beam: tuple | None = None
             ) -> np.ndarray:
    """(size, size) gain, 1 at the chip centre; strength 1 makes a flat floor equally bright everywhere.

    A partial TVG (strength < 1) applies that gain to the power `strength`, so a share of
    the flat floor's fall-off with range remains, as in chips from a sonar whose TVG does
    not quite follow spreading and grazing loss.
    """
    gain = (math.pi / exposure(positions, cos_power, beam)) / flat_floor_irradiance(positions, size, cos_power, beam)
    return gain if strength == 1 else gain**strength


@lru_cache(maxsize=8)
def _gamma_quantiles(looks: float) -> tuple[np.ndarray, np.ndarray]:
    """(z, q): the Gamma(looks, 1 / looks) quantile at the standard-normal quantile z, tabulated."""
    from scipy.special import gammaincinv, ndtr

    # z every 1/64: at 1 look its interpolation is within 3e-5 (of a mean of 1) of a table 8 times finer, far
    # under a gray level, and it costs 1 ms, not 6: a preset draws each chip's looks anew
    z = np.linspace(-8.0, 8.0, 1025)
    return z, gammaincinv(looks, np.clip(ndtr(z), 1e-300, 1 - 1e-16)) / looks


def correlated_gamma(rng: np.random.Generator, looks: float, size: int, sigma_rows: float, sigma_cols: float
                     ) -> np.ndarray:
    """(size, size) gamma speckle (mean 1, variance 1 / looks) correlated over a Gaussian cell (sigma in px).

    A Gaussian field smoothed by the cell is mapped through the normal CDF and the gamma
    quantile (a Gaussian copula): each pixel keeps the L-look gamma distribution, and
    neighbours within a cell are alike, as in an image whose resolution cell spans pixels.
    """
    white = rng.standard_normal((size, size))
    fy, fx = np.fft.fftfreq(size)[:, None], np.fft.rfftfreq(size)[None, :]
    response = np.exp(-2 * np.pi**2 * ((fy * sigma_rows) ** 2 + (fx * sigma_cols) ** 2))
    field = np.fft.irfft2(np.fft.rfft2(white) * response, s=(size, size))
    field = (field - field.mean()) / field.std()
    z, q = _gamma_quantiles(float(looks))
    return _interp_uniform(field, z, q)


def _interp_uniform(x: np.ndarray, z: np.ndarray, q: np.ndarray) -> np.ndarray:
    """np.interp(x, z, q) for evenly spaced z, by index arithmetic instead of a search: 3x faster at 256²."""
    position = (np.clip(x, z[0], z[-1]) - z[0]) * ((len(z) - 1) / (z[-1] - z[0]))
    left = np.minimum(position.astype(np.intp), len(z) - 2)
    return q[left] + (position - left) * (q[left + 1] - q[left])


def swing_noise(rng: np.random.Generator, rows: int, length: float) -> np.ndarray:
    """(rows,) Gaussian noise along track of unit sd, correlated over `length` px (a Gaussian's sigma)."""
    pad = int(4 * length)
    noise = ndimage.gaussian_filter1d(rng.standard_normal(rows + 2 * pad), length)[pad:pad + rows]
    return noise / max(noise.std(), 1e-9)


def wander_field(shape: tuple[int, int], rng: np.random.Generator, length: float) -> np.ndarray:
    """(H, W): a field of unit spread, smooth over `length` px (a Gaussian's sigma)."""
    field = ndimage.gaussian_filter(rng.standard_normal(shape), length, mode="wrap")
    return field / max(field.std(), 1e-12)


def wandered(speckle: np.ndarray, wander: float, field: np.ndarray) -> np.ndarray:
    """(H, W) >= 0: a speckle whose deviations from its mean are scaled by exp(wander x field - wander²): its
    contrast wanders from patch to patch as the field does, its mean square kept."""
    mean = speckle.mean()
    return np.maximum(mean + (speckle - mean) * np.exp(wander * field - wander ** 2), 0.0)


def post_fields(scene: Scene, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) speckle (mean 1; all 1 when off) and offset (noise floor x speckle + noise; gray levels).

    With `seafloor.patchiness` the speckle is multiplied by a correlated gamma texture (mean 1,
    std / mean = patchiness, patches of `patch_size`): the compound (K-distribution) model of
    seafloor clutter, where the sediment's backscatter strength varies in patches under the
    speckle. It multiplies every echo, as the speckle does; the noise floor stays untextured.
    With `post.speckle_wander` the speckle's deviations from its mean are scaled by exp(w x field - w²), a
    field of unit sd smooth over `speckle_wander_length`: its contrast wanders from patch to patch, as real
    chips' does, where a speckle of one number of looks is equally grainy everywhere.
    With `post.gain_swing` each row along track (a ping) is multiplied by exp(gain_swing x n), n
    of unit sd correlated over `gain_swing_length`: the swath's gain swinging from ping to ping,
    which real chips show as rows brighter or darker as a whole. It too spares the noise floor.
    """
    post = scene.post
    rng = np.random.default_rng([scene.seed, 11])
    speckle = np.ones((size, size))
    noise = np.zeros((size, size))
    pixel = scene.sonar.chip_size / size  # m
    if post.speckle_looks > 0:
        if post.speckle_cell_range > 0 or post.speckle_cell_track > 0:
            speckle = correlated_gamma(rng, post.speckle_looks, size, post.speckle_cell_track / pixel / FWHM_PER_SIGMA,
                                       post.speckle_cell_range / pixel / FWHM_PER_SIGMA)
        else:
            speckle = rng.gamma(post.speckle_looks, 1.0 / post.speckle_looks, size=(size, size))
        if post.speckle_wander > 0:  # its own stream: the wander changes none of the chip's other draws
            field = wander_field((size, size), np.random.default_rng([scene.seed, 14]),
                                 post.speckle_wander_length / pixel)
            speckle = wandered(speckle, post.speckle_wander, field)
    if post.noise_std > 0:
        noise = rng.normal(0.0, post.noise_std, size=(size, size))
    offset = noise + post.noise_floor * speckle  # the background has no sediment texture
    floor = scene.seafloor
    if floor.patchiness > 0:  # its own stream: the texture changes none of the chip's other draws
        sigma = floor.patch_size / pixel / FWHM_PER_SIGMA
        speckle = speckle * correlated_gamma(np.random.default_rng([scene.seed, 12]), floor.patchiness**-2, size,
                                             sigma, sigma)
    if floor.mosaic_contrast != 1:  # its own stream too
        sigma = floor.mosaic_size / pixel / FWHM_PER_SIGMA
        speckle = speckle * mosaic(np.random.default_rng([scene.seed, 15]), size, sigma, floor.mosaic_share,
                                   floor.mosaic_contrast)
    if post.gain_swing > 0:  # its own stream too
        rows = swing_noise(np.random.default_rng([scene.seed, 13]), size, post.gain_swing_length / pixel)
        speckle = speckle * np.exp(post.gain_swing * rows)[:, None]
    return speckle, offset


def post_maps(scene: Scene, g: Geometry) -> Maps:
    """(H, W) time-varying gain (1 when off), speckle (mean 1) and additive offset of `scene`."""
    post = scene.post
    if post.tvg:
        gain = tvg_gain(g.emitter_positions, g.size, g.floor.cos_power, post.tvg_strength, g.beam)
    else:
        gain = np.ones((g.size, g.size))
    return (gain, *post_fields(scene, g.size))


def postprocess(radiance: np.ndarray, maps: Maps) -> np.ndarray:
    """(H, W) radiance -> (H, W) float32 chip in [0, 1]: radiance x gain x speckle + offset, clipped."""
    gain, speckle, offset = maps
    return np.clip(radiance.astype(np.float64) * gain * speckle + offset, 0.0, 1.0).astype(np.float32)
