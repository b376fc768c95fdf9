"""The seabed as a surface in metres (numpy only): power-law rough surface, sand ripples, rocks.

The floor of a scene is one function z(x, y) of position in metres, whatever the image
size: the rough part is drawn on a fixed grid of FLOOR_SAMPLES x FLOOR_SAMPLES points over
the chip and interpolated bilinearly, as is the sideways wander of sinuous ripples' crests;
ripples and rocks are closed-form. A render at n pixels samples that surface at its
(n+1) x (n+1) vertices (exactly on the grid points when n divides FLOOR_SAMPLES), so 64, 128
and 256 px renders of one (seed, index) show the same seafloor, and the 64 px cross-check
checks the floor a 256 px render shows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sasmi.scene.model import Seafloor

FLOOR_SAMPLES = 256  # rough-surface grid points across the chip (a fast FFT size)
ROCK_REACH = 7.5  # sigmas: a rock ends where it adds exp(-28) < 1e-12 of its height, below float32's resolution


def _rock(d2: np.ndarray, r: float) -> np.ndarray:
    """Height (m) of a rock of radius r at squared distance d2 (m^2) from its centre: a Gaussian, sigma r / 2."""
    return r * np.exp(-d2 / (2 * (r / 2) ** 2))


@dataclass(frozen=True)
class Surface:
    """z(x, y) in metres; x (range) and y (along track) in metres from the chip centre."""
    chip_size: float
    rough: np.ndarray  # (FLOOR_SAMPLES + 1,) * 2, periodic grid over the chip; row = y, col = x
    ripple_amplitude: float
    ripple_wavelength: float
    ripple_direction: float  # deg from +x
    ripple_phase: float
    rocks: tuple[tuple[float, float, float], ...]  # (centre x, centre y, radius), m
    ripple_wander: np.ndarray | None = None  # as rough: radians added to the ripples' phase (sinuous crests)
    ripple_sharpness: float = 1.0  # Seafloor.ripple_sharpness: 1 a sinusoid

    def at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Heights (m) at points x, y (any equal shapes, m from the chip centre; clamped to the chip)."""
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        return self._add_shapes(self._rough_at(x, y), x, y)

    def _add_shapes(self, heights: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """`heights` plus the ripples and rocks at x, y."""
        heights = heights + self._ripples(x, y)
        for cx, cy, r in self.rocks:
            d2 = (x - cx) ** 2 + (y - cy) ** 2
            heights = heights + np.where(d2 <= (ROCK_REACH * r / 2) ** 2, _rock(d2, r), 0.0)
        return heights

    def _add_shapes_grid(self, heights: np.ndarray, coords: np.ndarray) -> np.ndarray:
        """`_add_shapes` on the grid coords x coords (row = y, col = x), each rock only within its reach:
        the same heights at a fraction of the cost (30 rocks over the whole grid cost more than the FFT)."""
        x, y = np.meshgrid(coords, coords)
        heights = heights + self._ripples(x, y)
        for cx, cy, r in self.rocks:
            reach = ROCK_REACH * r / 2
            c0, c1 = np.searchsorted(coords, cx - reach), np.searchsorted(coords, cx + reach, side="right")
            r0, r1 = np.searchsorted(coords, cy - reach), np.searchsorted(coords, cy + reach, side="right")
            d2 = (coords[c0:c1][None, :] - cx) ** 2 + (coords[r0:r1][:, None] - cy) ** 2
            heights[r0:r1, c0:c1] += np.where(d2 <= reach**2, _rock(d2, r), 0.0)
        return heights

    def _ripples(self, x: np.ndarray, y: np.ndarray) -> np.ndarray | float:
        if self.ripple_amplitude <= 0:
            return 0.0
        theta = np.deg2rad(self.ripple_direction)
        phase = 2 * np.pi * (x * np.cos(theta) + y * np.sin(theta)) / self.ripple_wavelength + self.ripple_phase
        if self.ripple_wander is not None:
            phase = phase + self._grid_at(self.ripple_wander, x, y)
        if self.ripple_sharpness == 1:  # the sine itself: every sinusoidal floor renders bit for bit as before
            return self.ripple_amplitude * np.sin(phase)
        return self.ripple_amplitude * crest_profile(np.sin(phase), self.ripple_sharpness)

    def _rough_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._grid_at(self.rough, x, y)

    def _grid_at(self, h: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """A periodic grid over the chip (row = y, col = x) interpolated bilinearly at x, y."""
        n = h.shape[0] - 1
        u = np.clip((x + self.chip_size / 2) / self.chip_size * n, 0, n)
        v = np.clip((y + self.chip_size / 2) / self.chip_size * n, 0, n)
        c0, r0 = np.minimum(u.astype(np.int64), n - 1), np.minimum(v.astype(np.int64), n - 1)
        fu, fv = u - c0, v - r0
        return ((1 - fv) * ((1 - fu) * h[r0, c0] + fu * h[r0, c0 + 1])
                + fv * ((1 - fu) * h[r0 + 1, c0] + fu * h[r0 + 1, c0 + 1]))

    def grid(self, n: int) -> np.ndarray:
        """(n+1, n+1) heights (m) at the vertices of an n x n grid spanning the chip; row = y, col = x."""
        coords = np.linspace(-self.chip_size / 2, self.chip_size / 2, n + 1)
        samples = self.rough.shape[0] - 1
        if samples % n == 0:  # the vertices are grid points: take them (the same values, no interpolation cost)
            rough = self.rough[::samples // n, ::samples // n]
        else:
            x, y = np.meshgrid(coords, coords)
            rough = self._rough_at(x, y)
        return self._add_shapes_grid(rough, coords)


def crest_profile(sine: np.ndarray, sharpness: float) -> np.ndarray:
    """A ripple's height in amplitudes at phase sin⁻¹(`sine`): ((1 + sine) / 2)^sharpness less its mean over a
    wavelength, scaled so that crests stand 1 above the mean level. 1 is the sinusoid; larger ones narrow the crests
    between flat troughs, as sand waves' (a lit crest a narrow bright band, not half the wavelength)."""
    mean = math.exp(math.lgamma(sharpness + 0.5) - math.lgamma(sharpness + 1)) / math.sqrt(math.pi)
    return (((1 + sine) / 2) ** sharpness - mean) / (1 - mean)


def surface(floor: Seafloor, chip_size: float, seed: int) -> Surface:
    """The seabed of a scene. Draw order (rough surface, ripple phase, rocks) from one generator, so a
    floor without rocks has the same rough surface and ripples (the differentiable render relies on it)."""
    rng = np.random.default_rng([seed, 7])
    n = FLOOR_SAMPLES
    rough = np.zeros((n + 1, n + 1))
    if floor.rms_height > 0:
        # The spectrum (1 + (k L)^2)^(-beta/2), L the correlation length, beta the spectral exponent,
        # filters Gaussian noise on the periodic n x n grid; the (n+1)-th row and column repeat the first.
        spacing = chip_size / n
        kx, ky = np.meshgrid(2 * np.pi * np.fft.rfftfreq(n, d=spacing), 2 * np.pi * np.fft.fftfreq(n, d=spacing))
        spectrum = (1 + (kx**2 + ky**2) * floor.correlation_length**2) ** (-floor.spectral_exponent / 2)
        noise = np.fft.rfft2(rng.standard_normal((n, n)))
        field = np.fft.irfft2(noise * np.sqrt(spectrum), s=(n, n))
        field -= field.mean()
        std = field.std()
        if std > 0:
            rough = np.pad(field, ((0, 1), (0, 1)), mode="wrap") * (floor.rms_height / std)
    phase = float(rng.uniform(0, 2 * np.pi)) if floor.ripple_amplitude > 0 else 0.0
    wander = None
    if floor.ripple_amplitude > 0 and floor.ripple_sinuosity > 0:  # its own stream: straight ripples keep their draws
        wander = 2 * np.pi * floor.ripple_sinuosity * _wander(np.random.default_rng([seed, 8]), n,
                                                              floor.ripple_wavelength / (chip_size / n))
    return Surface(chip_size=chip_size, rough=rough, ripple_amplitude=floor.ripple_amplitude,
                   ripple_wavelength=floor.ripple_wavelength, ripple_direction=floor.ripple_direction,
                   ripple_phase=phase, rocks=_draw_rocks(rng, floor, chip_size), ripple_wander=wander,
                   ripple_sharpness=floor.ripple_sharpness)


def _wander(rng: np.random.Generator, n: int, sigma: float) -> np.ndarray:
    """(n+1, n+1) periodic Gaussian field of unit sd smoothed over `sigma` grid steps: a crest wanders sideways
    over about a wavelength along itself, as real sand ripples' crests bend and fork."""
    fy, fx = np.fft.fftfreq(n)[:, None], np.fft.rfftfreq(n)[None, :]
    response = np.exp(-2 * np.pi**2 * (fy**2 + fx**2) * sigma**2)
    field = np.fft.irfft2(np.fft.rfft2(rng.standard_normal((n, n))) * response, s=(n, n))
    return np.pad(field / max(field.std(), 1e-12), ((0, 1), (0, 1)), mode="wrap")


def rocks(floor: Seafloor, chip_size: float, seed: int) -> tuple[tuple[float, float, float], ...]:
    """`surface(floor, chip_size, seed).rocks` without making the rough surface: the same draws, in the
    same order (the rough surface's noise and the ripple phase come first), skipping the FFT."""
    rng = np.random.default_rng([seed, 7])
    if floor.rms_height > 0:
        rng.standard_normal((FLOOR_SAMPLES, FLOOR_SAMPLES))
    if floor.ripple_amplitude > 0:
        rng.uniform(0, 2 * np.pi)
    return _draw_rocks(rng, floor, chip_size)


def _draw_rocks(rng: np.random.Generator, floor: Seafloor, chip_size: float
                ) -> tuple[tuple[float, float, float], ...]:
    """(centre x, centre y, radius) in m per rock (a Gaussian bump of height radius, sigma radius / 2)."""
    out = []
    for _ in range(floor.rocks):
        cx, cy = rng.uniform(-chip_size / 2, chip_size / 2, size=2)
        out.append((float(cx), float(cy), float(floor.rock_radius * rng.uniform(0.6, 1.4))))
    return tuple(out)

