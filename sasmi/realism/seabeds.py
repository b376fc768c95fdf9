"""Real-like floors without real chips: a real floor's seabed and speckle spectra under fresh random phases.

A floor chip blurred over SEABED px is its seabed (`seabed_of`). Seen at COARSE px, the log of a seabed
is its mean, its range profile and a field whose Fourier amplitudes say how rough it is at each scale
and in each direction. Drawing that field's phases afresh makes a new seabed of the same character that
is no real chip (phase randomisation, Theiler et al. 1992). What is left of the chip over its seabed is
its speckle: its grain (power spectrum) and its gray levels (quantiles) are the sonar's, and a render's
speckle has neither, which a small classifier sees at once (docs/gan.md, *Drawn floors*). A speckle of
both is drawn by iterating between the two (IAAFT, Schreiber & Schmitz 1996), starting from a coherent
speckle, whose bright pixels come in grains as a real one's do (started from shuffled levels, they stand
alone among dim ones). Real speckle is not quite independent of its seabed: its contrast falls where the
seabed is bright (the sonar's noise tells in the dark), which a seabed times a level-blind speckle lacks
and a small classifier sees; each speckle chip's slope of contrast against level is kept, its speckle
evened out by it before its grain and levels are taken, and a drawn speckle given it back over its new
seabed (`contrast_slope`). Beyond its level, a real speckle's contrast also wanders from patch to patch,
where an IAAFT speckle's is the same everywhere; each chip's excess wander is kept and a drawn speckle's
contrast made to wander as much (`contrast_wander`). A real chip's display bends its brightest levels
under a ceiling, where a seabed times a speckle clips to white in clusters: a drawn floor is bent under
its speckle chip's brightest level (sasmi.realism.display). A seabeds file keeps statistics, no image:
each seafloor chip's mean, profile and amplitudes, and each speckle chip's (floor chips, or target
chips' floors) spectrum, quantiles, contrast slope, wander and brightest level. The shipped one
(sasmi/weights/seabeds.pt, docs/models.md) holds those of the shared target chips' sonar.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from sasmi.errors import SasmiError
from sasmi.images import list_images
from sasmi.realism.display import bent
from sasmi.render.post import wander_field, wandered

COARSE = 32      # px: a seabed (blurred over SEABED px at 128) keeps nothing finer than this grid shows
SEABED = 4.0     # px at 128: a floor chip blurred by this is its seabed (bands, patches); what is left, its speckle
SPECKLE = 128    # px: speckle is drawn at the real chips' size; its power spectrum is kept on half that grid
LEVELS = 257     # quantiles of the speckle's gray levels
IAAFT_ROUNDS = 10  # spectrum and levels agree to a few per cent after this many (Schreiber & Schmitz 1996)
# rows either side of a target chip's centre row left out of its speckle: target chips are cut centred on the
# target along track, and its highlight and shadow span at most this many rows at 128 px (`sasmi stats`)
TARGET_ROWS = 24
CONTRAST_BLOCK = 8  # px at 128: blocks in which a speckle's contrast is set against its seabed's level
# the contrast slopes kept: 90 % of the shared target chips' floors lie within -0.9 and 0.2; 5 % reach -1, a
# few dark blocks deciding the fit
SLOPE_LIMIT = 1.0
# px at 128: the patches over which a speckle's contrast wanders. On the shared target chips' floors the log
# contrast of 8 px blocks, less its level's part, correlates 0.24 with the next block's (16 px blocks: 0.19);
# drawn with a field smooth over 8 px, 0.28 (0.18)
WANDER_LENGTH = 8.0
WANDER_LIMIT = 0.5  # the most wander kept: exp(±2 × 0.5) swings contrast by e, far past the shared chips' (≤ 0.3)
KIND = "seabeds"
TABLES = ("mean", "profile", "amplitude", "speckle_power", "speckle_levels", "speckle_slope", "speckle_wander",
          "speckle_ceiling")


@dataclass(frozen=True)
class Seabeds:
    mean: np.ndarray        # (N,) each chip's mean log seabed
    profile: np.ndarray     # (N, COARSE) its log seabed's range profile, less the mean
    amplitude: np.ndarray   # (N, COARSE, COARSE // 2 + 1) |rfft2| of the rest
    speckle_power: np.ndarray   # (M, SPECKLE // 2, SPECKLE // 4 + 1) a speckle's power spectrum, smoothed, no mean
    speckle_levels: np.ndarray  # (M, LEVELS) its quantiles; M: the floor chips, or the target chips' floors
    speckle_slope: np.ndarray   # (M,) its contrast's slope against its seabed's level, log-log (`contrast_slope`)
    speckle_wander: np.ndarray  # (M,) the std of the log of its contrast's wander beyond level (`contrast_wander`)
    speckle_ceiling: np.ndarray  # (M,) its chip's brightest gray level, a drawn floor's ceiling (inf: none)
    path: Path | None = None

    def shapes_agree(self) -> bool:
        n, m = len(self.mean), len(self.speckle_levels)
        return (self.mean.ndim == 1 and n > 0 and m > 0 and self.profile.shape == (n, COARSE)
                and self.amplitude.shape == (n, COARSE, COARSE // 2 + 1)
                and self.speckle_power.shape == (m, SPECKLE // 2, SPECKLE // 4 + 1)
                and self.speckle_levels.shape == (m, LEVELS) and self.speckle_slope.shape == (m,)
                and self.speckle_wander.shape == (m,) and self.speckle_ceiling.shape == (m,))


def log_seabed(chip01: np.ndarray) -> np.ndarray:
    """(COARSE, COARSE): the log seabed of a floor chip (any size, in [0, 1]) on the coarse grid."""
    import torch
    import torch.nn.functional as F

    scale = chip01.shape[0] / 128  # SEABED is in px of a 128 px chip
    seabed = ndimage.gaussian_filter(chip01.astype(np.float64), SEABED * scale) + 1e-3
    coarse = F.interpolate(torch.from_numpy(seabed)[None, None], size=(COARSE, COARSE), mode="area")
    return np.log(coarse[0, 0].numpy())


def seabed_of(chip01: np.ndarray) -> np.ndarray:
    """(H, W) > 0: a floor chip (in [0, 1], 128 px) blurred over SEABED px: its seabed."""
    return ndimage.gaussian_filter(chip01.astype(np.float64), SEABED) + 1e-3


def speckle_of(chip01: np.ndarray) -> np.ndarray:
    """(H, W): a floor chip (in [0, 1], 128 px) over its seabed: its speckle, under the multiplicative model."""
    return chip01 / seabed_of(chip01)


def _resized(x: np.ndarray, shape: tuple[int, int], mode: str, align_corners: bool = False) -> np.ndarray:
    import torch
    import torch.nn.functional as F

    return F.interpolate(torch.from_numpy(np.ascontiguousarray(x))[None, None], size=shape, mode=mode,
                         **({"align_corners": align_corners} if mode == "bilinear" else {}))[0, 0].numpy()


def speckle_spectrum(speckle: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(SPECKLE // 2, SPECKLE // 4 + 1): the power spectrum of the speckle's pixels where `keep`, less their mean,
    smoothed (one chip's is noise) and kept on half the grid: its grain, in a quarter the numbers.

    It is the transform of their autocorrelation, each lag averaged over the pixel pairs both kept
    (Blackman-Tukey: lags out to half the chip, tapered), so that rows left out bias no lag.
    """
    h, w = speckle.shape
    x = np.where(keep, speckle - speckle[keep].mean(), 0.0)
    pairs = np.fft.irfft2(np.abs(np.fft.rfft2(keep.astype(np.float64), s=(2 * h, 2 * w))) ** 2, s=(2 * h, 2 * w))
    sums = np.fft.irfft2(np.abs(np.fft.rfft2(x, s=(2 * h, 2 * w))) ** 2, s=(2 * h, 2 * w))
    rows, cols = np.r_[0:h // 2, -(h // 2):0], np.r_[0:w // 2, -(w // 2):0]   # lags, in FFT order
    acf = (sums / np.maximum(pairs, 1.0))[np.ix_(rows % (2 * h), cols % (2 * w))]
    taper = np.outer(1 - np.abs(rows) / (h // 2), 1 - np.abs(cols) / (w // 2))  # Bartlett: a power >= 0
    power = np.maximum(np.fft.rfft2(acf * taper).real, 0.0)
    smooth = ndimage.uniform_filter(power, 3, mode="wrap")
    return _resized(smooth, (SPECKLE // 2, SPECKLE // 4 + 1), "area")


def _block_contrast(speckle: np.ndarray, seabed: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(log mean seabed, log speckle std / mean) of the CONTRAST_BLOCK-px blocks wholly in `keep`."""
    b = CONTRAST_BLOCK
    blocks = lambda x: x[:x.shape[0] // b * b, :x.shape[1] // b * b].reshape(x.shape[0] // b, b, -1, b).swapaxes(1, 2)
    speckle, seabed = blocks(speckle), blocks(seabed)
    whole = blocks(keep).all(axis=(2, 3))
    contrast = speckle.std(axis=(2, 3)) / np.maximum(speckle.mean(axis=(2, 3)), 1e-9)
    return np.log(seabed.mean(axis=(2, 3))[whole]), np.log(np.maximum(contrast[whole], 1e-9))


def contrast_slope(chip01: np.ndarray, keep: np.ndarray) -> float:
    """How a floor chip's speckle contrast follows its seabed's level: the slope of log(std / mean) of the
    speckle against log(mean seabed) over CONTRAST_BLOCK-px blocks wholly in `keep`, within ±SLOPE_LIMIT.

    0 under the multiplicative model; real floors about −0.4: a dark patch is grainier, as a
    sonar's additive noise makes it. chip01: (128, 128) in [0, 1]; keep: (128, 128) bool.
    """
    seabed = seabed_of(chip01)
    return _slope(chip01 / seabed, seabed, keep)


def _slope(speckle: np.ndarray, seabed: np.ndarray, keep: np.ndarray) -> float:
    level, contrast = _block_contrast(speckle, seabed, keep)
    if len(level) < 3 or np.ptp(level) < 1e-6:
        return 0.0
    return float(np.clip(np.polyfit(level, contrast, 1)[0], -SLOPE_LIMIT, SLOPE_LIMIT))


def _unexplained(level: np.ndarray, contrast: np.ndarray) -> float:
    """The spread of the blocks' log contrast that their level does not explain (a line's residuals)."""
    if len(level) < 3 or np.ptp(level) < 1e-6:
        return float(contrast.std()) if len(contrast) else 0.0
    return float((contrast - np.polyval(np.polyfit(level, contrast, 1), level)).std())


def contrast_wander(speckle: np.ndarray, seabed: np.ndarray, keep: np.ndarray, stationary: np.ndarray,
                    field: np.ndarray) -> float:
    """How much a floor chip's speckle (over its seabed) wanders beyond its level: the wander under which
    `stationary`, an IAAFT speckle of the chip's own grain and levels (whose blocks differ by chance alone),
    spreads its blocks' log contrast beyond what the level explains as the chip's speckle does (`wandered`
    over `field`, a `wander_field`), within [0, WANDER_LIMIT]. Real target chips' floors: about 0.1-0.3."""
    from scipy.optimize import brentq

    real = _unexplained(*_block_contrast(speckle, seabed, keep))
    excess = lambda w: _unexplained(*_block_contrast(wandered(stationary, w, field), seabed, keep)) - real
    if excess(0.0) >= 0.0:
        return 0.0
    if excess(WANDER_LIMIT) <= 0.0:
        return WANDER_LIMIT
    return float(brentq(excess, 0.0, WANDER_LIMIT, xtol=1e-3))


def _level_factor(seabed: np.ndarray, slope: float, where: np.ndarray | None = None) -> np.ndarray:
    """(H, W): how much a speckle's deviations from its mean grow over `seabed` with `slope` (1 at its median)."""
    median = np.median(seabed if where is None else seabed[where])
    return np.clip(seabed / median, 0.05, 20.0) ** slope


def _speckle_tables(chips: list[np.ndarray], keep: np.ndarray) -> tuple[np.ndarray, ...]:
    powers, levels, slopes, wanders = [], [], [], []
    for i, chip in enumerate(chips):
        seabed = seabed_of(chip)
        speckle = chip / seabed  # speckle_of, its seabed computed once
        slope, mean = _slope(speckle, seabed, keep), speckle[keep].mean()
        even = mean + (speckle - mean) / _level_factor(seabed, slope, keep)  # its contrast made level-blind
        powers.append(speckle_spectrum(even, keep))
        levels.append(np.quantile(even[keep], np.linspace(0.0, 1.0, LEVELS)))
        slopes.append(slope)
        rng = np.random.default_rng(i)  # a stream per chip: the file's bytes fixed
        stationary = _iaaft(powers[-1], levels[-1], rng)
        field = wander_field(stationary.shape, rng, WANDER_LENGTH)
        wanders.append(contrast_wander(speckle, seabed, keep, stationary, field))
    brightest = np.array([chip.max() for chip in chips])
    return np.stack(powers), np.stack(levels), np.array(slopes), np.array(wanders), brightest


def fit_seabeds(floors: str | os.PathLike, targets: str | os.PathLike | None = None) -> Seabeds:
    """The Seabeds of every floor chip in a folder; the speckle of the target chips of `targets` where given.

    A sonar's target chips and seafloor chips may be cut from different images, whose floors'
    speckle differs (the shared MILCO seafloor chips show fewer looks and a brighter tail than the
    floors of its target chips): chips of targets must match the floors of target chips. A target
    chip's speckle is taken from its rows clear of the target (TARGET_ROWS).
    """
    from sasmi.preprocess import load_image

    def chips_of(folder) -> list[np.ndarray]:
        paths = list_images(folder)
        if not paths:
            raise SasmiError(f"{folder}: no image (png, jpg, tif, tiff, npy) in it")
        return [load_image(p, SPECKLE).astype(np.float64) for p in paths]

    chips = chips_of(floors)
    logs = np.stack([log_seabed(chip) for chip in chips])                         # (N, C, C)
    mean = logs.mean(axis=(1, 2))
    profile = logs.mean(axis=1) - mean[:, None]                                    # (N, C): per range column
    rest = logs - mean[:, None, None] - profile[:, None, :]
    keep = np.ones((SPECKLE, SPECKLE), bool)
    if targets is not None:
        keep[SPECKLE // 2 - TARGET_ROWS:SPECKLE // 2 + TARGET_ROWS] = False
    return Seabeds(mean, profile, np.abs(np.fft.rfft2(rest)),
                   *_speckle_tables(chips if targets is None else chips_of(targets), keep))


def draw_seabed(seabeds: Seabeds, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) > 0: a new seabed, one chip's mean, profile and amplitudes under random phases, at `shape`."""
    k = int(rng.integers(len(seabeds.mean)))
    # the phases of white noise's transform: random, and exactly those of a real field
    phase = np.angle(np.fft.rfft2(rng.standard_normal((COARSE, COARSE))))
    rest = np.fft.irfft2(seabeds.amplitude[k] * np.exp(1j * phase), s=(COARSE, COARSE))
    log = seabeds.mean[k] + seabeds.profile[k][None, :] + rest
    # no blur here: the amplitudes are of a seabed already blurred over SEABED px; blurred again, its relief
    # at 4-8 px would be half its source's
    return _resized(np.exp(log), shape, "bilinear")


def draw_speckle(seabeds: Seabeds, chip: int, rng: np.random.Generator, coherent: bool = True) -> np.ndarray:
    """(SPECKLE, SPECKLE) > 0: a new speckle of chip `chip`'s grain and levels; `coherent=False`: a shuffled start."""
    return _iaaft(seabeds.speckle_power[chip], seabeds.speckle_levels[chip], rng, coherent)


def coherent_speckle(power: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(SPECKLE, SPECKLE) >= 0: |z|² of a complex Gaussian field z whose intensity has about the power spectrum
    `power` (SPECKLE, SPECKLE // 2 + 1): an intensity's autocorrelation is its field's, squared (Goodman)."""
    covariance = np.fft.irfft2(power, s=(SPECKLE, SPECKLE))
    field = np.sqrt(np.maximum(covariance / max(covariance[0, 0], 1e-300), 0.0))  # its correlation's magnitude
    field_power = np.maximum(np.fft.fft2(field).real, 0.0)
    white = rng.standard_normal((SPECKLE, SPECKLE)) + 1j * rng.standard_normal((SPECKLE, SPECKLE))
    return np.abs(np.fft.ifft2(np.sqrt(field_power) * np.fft.fft2(white))) ** 2


def _iaaft(speckle_power: np.ndarray, speckle_levels: np.ndarray, rng: np.random.Generator,
           coherent: bool = True) -> np.ndarray:
    power = np.maximum(_resized(speckle_power, (SPECKLE, SPECKLE // 2 + 1), "bilinear", align_corners=True), 0.0)
    power[0, 0] = 0.0  # the mean is the levels' to set
    amplitude = np.sqrt(power)
    levels = np.interp(np.linspace(0.0, 1.0, SPECKLE * SPECKLE), np.linspace(0.0, 1.0, LEVELS), speckle_levels)
    # the levels in a coherent speckle's order, not shuffled: the iterations keep much of its phases, whose bright
    # pixels come in grains as real ones do (a shuffle's stand alone among dim ones: benchmarks/speckle_grains.py)
    ranked = np.empty_like(levels)
    start = coherent_speckle(power, rng) if coherent else rng.random((SPECKLE, SPECKLE))
    ranked[np.argsort(start, axis=None)] = levels
    x = ranked.reshape(SPECKLE, SPECKLE).copy()
    for _ in range(IAAFT_ROUNDS):
        spectrum = np.fft.rfft2(x)
        # x's phases under the source's amplitudes: z |A| / |z| costs a third of exp(1j * angle(z))
        x = np.fft.irfft2(spectrum * (amplitude / np.maximum(np.abs(spectrum), 1e-300)), s=x.shape)
        ranked[np.argsort(x, axis=None)] = levels  # the levels back, in x's order
        x = ranked.reshape(x.shape)
    return x


def draw_floor(seabeds: Seabeds, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) >= 0: a drawn seabed under a drawn speckle, each of a chip drawn at random, at `shape` (speckle
    drawn at SPECKLE px, area-averaged or interpolated to `shape` as real chips are when loaded), the
    speckle's contrast wandering as its chip's and following the seabed's level by its chip's slope."""
    seabed = draw_seabed(seabeds, shape, rng)
    chip = int(rng.integers(len(seabeds.speckle_levels)))
    speckle = draw_speckle(seabeds, chip, rng)
    speckle = wandered(speckle, seabeds.speckle_wander[chip], wander_field(speckle.shape, rng, WANDER_LENGTH))
    if speckle.shape != tuple(shape):
        speckle = _resized(speckle, shape, "area" if shape[0] < SPECKLE else "bilinear")
    mean = speckle.mean()
    floor = seabed * np.maximum(mean + (speckle - mean) * _level_factor(seabed, seabeds.speckle_slope[chip]), 0.0)
    return bent(floor, seabeds.speckle_ceiling[chip])


def save_seabeds(seabeds: Seabeds, out: str | os.PathLike, about: dict | None = None) -> Path:
    """Write a seabeds file (tensors and plain types: loads with torch.load(weights_only=True))."""
    import torch

    from sasmi import __version__
    from sasmi.gan.run import FORMAT
    from sasmi.images import write_torch

    data = {"format": FORMAT, "sasmi": __version__, "kind": KIND, "about": about or {},
            "state": {name: torch.from_numpy(np.ascontiguousarray(getattr(seabeds, name), dtype=np.float32))
                      for name in TABLES}}
    return write_torch(out, data)


def load_seabeds(path: str | os.PathLike) -> Seabeds:
    """A seabeds file, or one SasmiError naming it."""
    import torch

    from sasmi.gan.run import FORMAT

    path = Path(path)
    if not path.is_file():
        raise SasmiError(f"{path}: no such seabeds file")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated, random bytes, a pickle carrying code
        raise SasmiError(f"{path}: not a readable seabeds file ({type(e).__name__})") from None
    if not isinstance(data, dict) or data.get("kind") != KIND:
        raise SasmiError(f"{path}: not a seabeds file (kind {data.get('kind') if isinstance(data, dict) else None!r})")
    if data.get("format") != FORMAT:
        raise SasmiError(f"{path}: seabeds format {data.get('format')!r}; this sasmi reads format {FORMAT} "
                         f"(written by {data.get('sasmi', 'another version')})")
    try:
        state = {k: v.double().numpy() for k, v in data["state"].items()}
        # a seabeds file without the wander or ceiling tables: its speckle is drawn without wander, unbent
        state.setdefault("speckle_wander", np.zeros(len(state["speckle_levels"])))
        state.setdefault("speckle_ceiling", np.full(len(state["speckle_levels"]), np.inf))
        seabeds = Seabeds(**{k: state[k] for k in TABLES}, path=path)
        ok = seabeds.shapes_agree()
    except (KeyError, TypeError, AttributeError):
        ok = False
    if not ok:
        raise SasmiError(f"{path}: its seabeds tables are missing or of the wrong shape (tables {', '.join(TABLES)})")
    return seabeds
