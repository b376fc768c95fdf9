"""Seafloor height arrays (numpy only): power-law rough surface, sand ripples, rocks."""
from __future__ import annotations

import numpy as np

from sasmi.scene import Seafloor


def height_array(floor: Seafloor, chip_size: float, n: int, seed: int) -> np.ndarray:
    """Heights (m) at an (n+1, n+1) vertex grid spanning the chip; row = along-track y, col = range x.

    The rough part is Gaussian noise filtered by the spectrum (1 + (k L)^2)^(-beta/2), with L
    the correlation length and beta the spectral exponent, then scaled to the rms height.
    """
    rng = np.random.default_rng([seed, 7])
    spacing = chip_size / n
    coords = np.arange(n + 1) * spacing - chip_size / 2
    x, y = np.meshgrid(coords, coords)  # (n+1, n+1), row = y
    heights = np.zeros_like(x)

    if floor.rms_height > 0:
        # Filter on the n x n periodic grid (n is a multiple of 16: fast FFT sizes) and repeat the
        # first row and column for the (n+1)-th vertices.
        kx, ky = np.meshgrid(2 * np.pi * np.fft.rfftfreq(n, d=spacing), 2 * np.pi * np.fft.fftfreq(n, d=spacing))
        spectrum = (1 + (kx**2 + ky**2) * floor.correlation_length**2) ** (-floor.spectral_exponent / 2)
        noise = np.fft.rfft2(rng.standard_normal((n, n)))
        rough = np.fft.irfft2(noise * np.sqrt(spectrum), s=(n, n))
        rough -= rough.mean()
        std = rough.std()
        if std > 0:
            heights += np.pad(rough, ((0, 1), (0, 1)), mode="wrap") * (floor.rms_height / std)

    if floor.ripple_amplitude > 0:
        theta = np.deg2rad(floor.ripple_direction)
        phase = rng.uniform(0, 2 * np.pi)
        heights += floor.ripple_amplitude * np.sin(
            2 * np.pi * (x * np.cos(theta) + y * np.sin(theta)) / floor.ripple_wavelength + phase)

    for _ in range(floor.rocks):
        cx, cy = rng.uniform(-chip_size / 2, chip_size / 2, size=2)
        r = floor.rock_radius * rng.uniform(0.6, 1.4)
        heights += r * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * (r / 2) ** 2))
    return heights


def height_at(heights: np.ndarray, chip_size: float, x: float, y: float) -> float:
    """Bilinear height at chip-centred (x, y) in metres."""
    n = heights.shape[0] - 1
    u = np.clip((x + chip_size / 2) / chip_size * n, 0, n)
    v = np.clip((y + chip_size / 2) / chip_size * n, 0, n)
    c0, r0 = min(int(u), n - 1), min(int(v), n - 1)
    fu, fv = u - c0, v - r0
    h = heights
    return float((1 - fv) * ((1 - fu) * h[r0, c0] + fu * h[r0, c0 + 1]) + fv * ((1 - fu) * h[r0 + 1, c0] + fu * h[r0 + 1, c0 + 1]))
