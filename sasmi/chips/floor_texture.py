"""Statistics of a chip's floor texture: its speckle, its grain and what stands out of it (sasmi.chips.stats).

Each takes a chip in [0, 1] and a bool mask of its floor (the chip less the target's boxes); pixel sizes are
stated at 128 px and scaled by the caller.
"""
from __future__ import annotations

import numpy as np
from skimage import filters

MIN_BLOCKS = 8      # floor blocks needed for a contrast's wander


def _blocks(x: np.ndarray, block: int) -> np.ndarray:
    """(blocks, block²): every whole `block`-px block of an (H, W) array at once, row by row."""
    rows, cols = x.shape[0] // block, x.shape[1] // block
    return x[:rows * block, :cols * block].reshape(rows, block, cols, block).swapaxes(1, 2).reshape(rows * cols, -1)


def speckle_looks(image01: np.ndarray, floor: np.ndarray, block: int) -> float:
    """Median over floor blocks of mean² / variance (the equivalent number of looks)."""
    b = _blocks(image01.astype(np.float64), block)
    mean, var = b.mean(axis=1), b.var(axis=1, ddof=1)
    usable = _blocks(floor, block).all(axis=1) & (mean > 4.0 / 255.0) & (var > 0)
    return float(np.median(mean[usable] ** 2 / var[usable])) if usable.any() else float("nan")


def unexplained_spread(level: np.ndarray, contrast: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """(N,): per row of (N, B) blocks, the spread of their log contrast that a least-squares line in their log
    level does not explain, over the `usable` ones (N, B) bool; NaN where under MIN_BLOCKS are. A flat row's
    slope is 0."""
    w = usable.astype(np.float64)
    n = w.sum(axis=1, keepdims=True)
    mean = lambda x: (w * x).sum(axis=1, keepdims=True) / np.maximum(n, 1)
    dl, dc = level - mean(level), contrast - mean(contrast)
    var = mean(dl * dl)
    slope = np.where(var > 1e-12, mean(dl * dc) / np.maximum(var, 1e-12), 0.0)
    spread = np.sqrt(mean((dc - slope * dl) ** 2))[:, 0]
    return np.where(n[:, 0] >= MIN_BLOCKS, spread, np.nan)


def contrast_wander(image01: np.ndarray, floor: np.ndarray, block: int) -> float:
    """How far the floor's speckle contrast wanders from block to block beyond what its level explains:
    `unexplained_spread` of log(std / mean) against log(mean) over whole floor blocks of `block` px above 4
    gray levels. Real target chips' floors about 0.2; a speckle of one number of looks, chance alone (0.1)."""
    b = _blocks(image01.astype(np.float64), block)
    mean, std = b.mean(axis=1), b.std(axis=1)
    usable = _blocks(floor, block).all(axis=1) & (mean > 4.0 / 255.0) & (std > 0)
    level, contrast = np.log(np.maximum(mean, 1e-9)), np.log(np.maximum(std, 1e-12) / np.maximum(mean, 1e-9))
    return float(unexplained_spread(level[None], contrast[None], usable[None])[0])


def floor_lowpass(image01: np.ndarray, floor: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The floor's local mean (a Gaussian of `sigma` px), where the floor is usable (above 2 gray levels), and the
    high-passed floor (image / local mean - 1 there, 0 elsewhere): one blur for every statistic below."""
    local = filters.gaussian(image01, sigma=sigma, preserve_range=True)
    ok = floor & (local > 2.0 / 255.0)
    return local, ok, np.where(ok, image01 / np.maximum(local, 1e-6) - 1.0, 0.0)


def floor_autocorrelation(hp: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    """1-px correlation coefficient of the high-passed floor `hp` where `ok`, along range and track."""

    def corr(a, b, both):
        if both.sum() < 16:
            return float("nan")
        a, b = a[both], b[both]
        a, b = a - a.mean(), b - b.mean()
        denom = np.sqrt((a * a).sum() * (b * b).sum())
        return float((a * b).sum() / denom) if denom > 0 else float("nan")

    along_range = corr(hp[:, :-1], hp[:, 1:], ok[:, :-1] & ok[:, 1:])
    along_track = corr(hp[:-1, :], hp[1:, :], ok[:-1, :] & ok[1:, :])
    return along_range, along_track


def seabed_contrast(local: np.ndarray, ok: np.ndarray) -> float:
    """std / mean over the usable floor `ok` of its low-pass `local` (the local mean the autocorrelation divides by):
    how strongly the seabed (sand waves, sediment boundaries, relief) stands out above the speckle: about 0.2 on the
    shared MILCO chips, 0.3 on the SASSED floors, 0.04 on a flat floor's 4-look speckle."""
    seabed = local[ok]
    return float(seabed.std() / seabed.mean()) if seabed.size >= 16 else float("nan")


def floor_periodicity(hp: np.ndarray, scale: float) -> float:
    """Strongest peak of the high-passed floor's power spectrum over its median, at wavelengths of
    2.5-11 px (at 128 px) in directions more than 10° off both axes: sand ripples as a regular
    stripe pattern, which none of the real chips show, give peaks far above speckle's flat
    spectrum. The axes are left out because sonar banding lies along them."""
    h, w = hp.shape
    window = np.hanning(h)[:, None] * np.hanning(w)[None, :]
    power = np.abs(np.fft.fftshift(np.fft.fft2(hp * window))) ** 2
    ky, kx = np.meshgrid(np.fft.fftshift(np.fft.fftfreq(h)), np.fft.fftshift(np.fft.fftfreq(w)), indexing="ij")
    cycles_per_px = np.hypot(kx, ky)
    angle = np.degrees(np.arctan2(ky, kx)) % 90.0  # 0 and 90: the two axes
    ring = ((cycles_per_px >= 1.0 / (11.0 * scale)) & (cycles_per_px <= 1.0 / (2.5 * scale))
            & (angle > 10.0) & (angle < 80.0))
    median = np.median(power[ring])
    return float(power[ring].max() / median) if median > 0 else float("nan")
