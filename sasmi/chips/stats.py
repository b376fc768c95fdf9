"""Image statistics of a folder of sonar chips, without masks: how far renders are from real chips.

Each chip goes through sasmi.preprocess.load_image to (size, size) in [0, 1]; range grows to
the right (+x, columns), along-track is y (rows). A target is a bright highlight whose peak
lies near the chip centre and a dark acoustic shadow that starts at the highlight and runs
to the right. Both are found on a speckle-smoothed image divided by the seafloor level of its
range column; a chip with no such pair (a seafloor chip) gets NaN target statistics. The
rest of the chip is "floor": speckle looks, autocorrelations and the range fall-off come
from it. Pixel thresholds are stated at 128 px and scale with `size`.

On a render set (masks/ beside images/: 0 seafloor, 1 target, 2 shadow) the same sizes are
also read from the masks, and the median |image estimate - mask| says how far to trust them.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from scipy import ndimage
from skimage import filters, measure, morphology

from sasmi.chips.floor_texture import (contrast_wander, floor_autocorrelation, floor_lowpass, floor_periodicity,
                                       seabed_contrast, speckle_looks)
from sasmi.errors import SasmiError
from sasmi.images import list_images
from sasmi.masks import read_mask
from sasmi.preprocess import check_size, load_image

# name -> (label in tables, unit). Order is the table's order.
STATISTICS = {
    "shadow_length": ("shadow length along range", "px"),
    "shadow_width": ("shadow width along track", "px"),
    "highlight_length": ("highlight length along range", "px"),
    "highlight_width": ("highlight width along track", "px"),
    "p50": ("gray level p50", "0-255"),
    "p99": ("gray level p99", "0-255"),
    "saturated": ("saturated pixels", "%"),
    "looks": ("speckle looks (floor blocks)", ""),
    "acf_range": ("1-px autocorr. along range", ""),
    "acf_track": ("1-px autocorr. along track", ""),
    "far_near": ("far-third / near-third", ""),
    # a swath's gain swings from ping to ping, so real chips show rows brighter or darker as a whole;
    # a floor chip blurred into a seabed keeps only its own strip's swing
    "bands": ("gain swing along track (log)", ""),
    "periodicity": ("floor periodicity (spectral peak / median)", ""),
    # a real floor's speckle is grainier in some patches than others; a speckle of one number of looks is not
    "wander": ("speckle contrast wander (floor blocks, log)", ""),
    # sand waves, sediment boundaries and relief stand out of the speckle on real floors, by more on some seabeds
    "seabed": ("seabed contrast (floor's low-pass, std / mean)", ""),
    "shadow_floor": ("shadow level / floor level", ""),
    # real target chips are cut centred on the contact: renders spread along track land off them in φ
    # even when every other row matches (docs/matching.md)
    "offset_track": ("target offset along track from the centre row", "px"),
    # and nearer than the centre along range (negative), so that the shadow falls in the chip: a preset places its
    # targets in metres, so a larger chip draws them nearer its centre in pixels, where a classifier tells them
    "offset_range": ("target offset along range from the centre column", "px"),
}
SWING_LAG = 3        # rows: past the speckle's correlation along track (real chips' 1-px acf about 0.2-0.35)
SWING_TREND = 32.0   # rows: slower swings are the seabed's, not the gain's
MASK_STATISTICS = ("shadow_length", "shadow_width", "highlight_length", "highlight_width")


@dataclass(frozen=True)
class Estimator:
    """Thresholds of the target finder, in pixels at 128 px (scaled with the chip size)."""
    centre_window: float = 18.0     # highlight peak within this many px of the centre (real chips: ±15)
    highlight_ratio: float = 2.0    # smoothed peak / floor level needed to call it a highlight
    highlight_level: float = 0.5    # the highlight is where the level exceeds this share of the peak's excess
    shadow_ratio: float = 0.6       # smoothed level / floor level below which a pixel is shadow
    shadow_depth: float = 0.35      # ...and somewhere inside it, below this: real shadows reach ~0.1
    shadow_sigma: float = 1.5       # smoothing (px) before the shadow threshold: speckle inside shadows
    shadow_gap: float = 16.0        # the shadow must start within this many px right of the highlight
    min_shadow_area: float = 12.0   # px² at 128 px
    block: int = 8                  # speckle-looks block side
    highpass_sigma: float = 3.0     # the floor's low-pass that the autocorrelation removes


@dataclass
class Target:
    highlight: tuple[int, int, int, int]  # (row0, col0, row1, col1), end exclusive, as skimage's bbox
    shadow: tuple[int, int, int, int]
    shadow_pixels: np.ndarray             # (H, W) bool


def floor_level(image01: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """(W,) the seafloor level of each range column: its median, smoothed along range.

    With `where` (H, W) bool, the median of each column's pixels there; a column with 8 or fewer
    takes the median of the other columns' levels.
    """
    if where is None:
        column = np.median(image01, axis=0)
    else:
        counts = where.sum(axis=0)
        ranked = np.sort(np.where(where, image01, np.inf), axis=0)  # each column's pixels there first, in order
        cols = np.arange(image01.shape[1])
        low, high = ranked[np.maximum(counts - 1, 0) // 2, cols], ranked[np.minimum(counts // 2, len(ranked) - 1), cols]
        column = np.where(counts % 2 == 1, high, (low + high) / 2)  # np.median's middle, or its two middle's mean
        column = np.where(counts > 8, column, np.nan)
        column = np.where(np.isfinite(column), column, np.nanmedian(column) if np.isfinite(column).any() else 1.0)
    level = ndimage.uniform_filter1d(column, size=9, mode="nearest")
    return np.maximum(level, 1.0 / 255.0)


def find_target(image01: np.ndarray, est: Estimator = Estimator()) -> Target | None:
    """The highlight near the centre and the shadow to its right, or None when the pair is absent."""
    h, w = image01.shape
    s = w / 128.0
    level = floor_level(image01)[None, :]
    bright = filters.gaussian(image01, sigma=1.0 * s, preserve_range=True) / level
    dark = filters.gaussian(image01, sigma=est.shadow_sigma * s, preserve_range=True) / level

    half = int(round(est.centre_window * s))
    r0, c0 = max(h // 2 - half, 0), max(w // 2 - half, 0)
    window = bright[r0:h // 2 + half, c0:w // 2 + half]
    pr, pc = np.unravel_index(np.argmax(window), window.shape)
    peak = window[pr, pc]
    if peak < est.highlight_ratio:
        return None
    # closing joins the pieces of one object (the two rims of a tyre) into one highlight
    hot = ndimage.binary_closing(bright >= 1.0 + est.highlight_level * (peak - 1.0),
                                 structure=morphology.disk(max(1, round(2 * s))))
    hot[r0 + pr, c0 + pc] = True
    hl_labels = measure.label(hot, connectivity=2)
    hl = measure.regionprops((hl_labels == hl_labels[r0 + pr, c0 + pc]).astype(np.uint8))[0]
    hr0, hc0, hr1, hc1 = hl.bbox

    shadow_mask = ndimage.binary_opening(dark < est.shadow_ratio, structure=morphology.disk(max(1, round(s))))
    labels = measure.label(shadow_mask, connectivity=2)
    pad = max(2, round(3 * s))
    best = None
    for region in measure.regionprops(labels):
        sr0, sc0, sr1, sc1 = region.bbox
        starts_at_highlight = sc0 <= hc1 + est.shadow_gap * s and region.centroid[1] > hl.centroid[1]
        beside = sr0 < hr1 + pad and sr1 > hr0 - pad
        deep = dark[region.coords[:, 0], region.coords[:, 1]].min() < est.shadow_depth
        if starts_at_highlight and beside and deep and region.area >= est.min_shadow_area * s * s:
            if best is None or region.area > best.area:
                best = region
    if best is None:
        return None
    return Target(highlight=tuple(hl.bbox), shadow=tuple(best.bbox), shadow_pixels=labels == best.label)


def _box_mask(shape: tuple[int, int], boxes, pad: int) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    for r0, c0, r1, c1 in boxes:
        m[max(r0 - pad, 0):r1 + pad, max(c0 - pad, 0):c1 + pad] = True
    return m


def profile_swing(log_profile: np.ndarray, valid: np.ndarray, scale: float) -> float:
    """The swings of a log row profile (rows along track): the square root of its autocovariance at
    SWING_LAG rows, after the trend over SWING_TREND rows is removed (both at 128 px, times `scale`).
    A row median's speckle noise is correlated over a row or two, so the lag leaves it out; 0 when the
    covariance is negative. `valid` (rows,) bool: the rows that count."""
    lag = max(1, round(SWING_LAG * scale))
    if valid.sum() <= lag + 2:
        return float("nan")
    filled = np.where(valid, log_profile, np.median(log_profile[valid]))
    detrended = filled - ndimage.gaussian_filter1d(filled, SWING_TREND * scale, mode="reflect")
    pairs = valid[:-lag] & valid[lag:]
    if not pairs.any():
        return float("nan")
    return float(np.sqrt(max(np.mean((detrended[:-lag] * detrended[lag:])[pairs]), 0.0)))


def gain_swing(image01: np.ndarray, floor: np.ndarray) -> float:
    """`profile_swing` of the log of each row's median over the floor, on rows with a quarter of their pixels
    or more on it."""
    h, w = image01.shape
    log_image = np.log(np.maximum(image01.astype(np.float64), 1.0 / 255.0))
    valid = floor.sum(axis=1) >= w // 4
    profile = np.zeros(h)
    profile[valid] = np.nanmedian(np.where(floor, log_image, np.nan)[valid], axis=1)  # all rows at once
    return profile_swing(profile, valid, w / 128.0)


def image_statistics(image01: np.ndarray, est: Estimator = Estimator()) -> dict[str, float]:
    """Every statistic of STATISTICS for one (S, S) chip in [0, 1]; target ones NaN without a target."""
    h, w = image01.shape
    s = w / 128.0
    out = {k: float("nan") for k in STATISTICS}
    gray = image01 * 255.0
    out["p50"], out["p99"] = (float(v) for v in np.percentile(gray, [50, 99]))
    out["saturated"] = float((gray >= 254.5).mean() * 100.0)
    floor = np.ones_like(image01, dtype=bool)
    target = find_target(image01, est)
    if target is not None:
        hr0, hc0, hr1, hc1 = target.highlight
        sr0, sc0, sr1, sc1 = target.shadow
        out.update(highlight_length=hc1 - hc0, highlight_width=hr1 - hr0, shadow_length=sc1 - sc0,
                   shadow_width=sr1 - sr0, offset_track=abs((hr0 + hr1 - 1) / 2 - (h - 1) / 2),
                   offset_range=(hc0 + hc1 - 1) / 2 - (w - 1) / 2)
        level = floor_level(image01)
        cols = np.nonzero(target.shadow_pixels.any(axis=0))[0]
        out["shadow_floor"] = float(np.median(image01[target.shadow_pixels]) / np.mean(level[cols]))
        floor = ~_box_mask(image01.shape, [target.highlight, target.shadow], pad=max(2, round(3 * s)))
    out["looks"] = speckle_looks(image01, floor, max(4, round(est.block * s)))
    local, ok, hp = floor_lowpass(image01, floor, est.highpass_sigma * s)
    out["acf_range"], out["acf_track"] = floor_autocorrelation(hp, ok)
    out["periodicity"] = floor_periodicity(hp, s)
    out["bands"] = gain_swing(image01, floor)
    out["wander"] = contrast_wander(image01, floor, max(4, round(est.block * s)))
    out["seabed"] = seabed_contrast(local, ok)
    third = w // 3
    near, far = image01[:, :third][floor[:, :third]], image01[:, -third:][floor[:, -third:]]
    if near.size and far.size and np.median(near) > 0:
        out["far_near"] = float(np.median(far) / np.median(near))
    return {k: float(v) for k, v in out.items()}


def mask_sizes(mask: np.ndarray) -> dict[str, float]:
    """Shadow and target extents (px) of a render mask (0 floor, 1 target, 2 shadow); NaN where absent."""
    out = {}
    for name, value in (("shadow", 2), ("highlight", 1)):
        rows, cols = np.nonzero(mask == value)
        out[f"{name}_length"] = float(np.ptp(cols) + 1) if cols.size else float("nan")
        out[f"{name}_width"] = float(np.ptp(rows) + 1) if rows.size else float("nan")
    return out


def _load_mask(path: Path, size: int) -> np.ndarray:
    mask = read_mask(path)  # ids, whether palette or gray; one line naming the file when unreadable
    if mask.shape != (size, size):
        if mask.shape[0] != mask.shape[1]:
            raise SasmiError(f"{path}: a render mask must be square to compare at --size {size}")
        mask = np.asarray(Image.fromarray(mask).resize((size, size), Image.NEAREST))
    return mask


def summarize(values: np.ndarray) -> dict[str, float]:
    """Median, quartiles and count of the finite values (NaN summary when none)."""
    v = values[np.isfinite(values)]
    if not v.size:
        return {"median": float("nan"), "q25": float("nan"), "q75": float("nan"), "n": 0}
    q25, median, q75 = np.percentile(v, [25, 50, 75])
    return {"median": float(median), "q25": float(q25), "q75": float(q75), "n": int(v.size)}


def chip_statistics(folder: str | os.PathLike, size: int = 128, est: Estimator = Estimator()) -> dict:
    """Per-chip arrays and a median/IQR summary of every statistic over a folder of chips.

    Returns {"folder", "size", "chips" (file names), "per_chip": {stat: (N,) array},
    "summary": {stat: {median, q25, q75, n}}, "targets_found" (fraction of chips), and on a
    render set "mask_error": {stat: median |image - mask|} and "mask_per_chip"}.
    """
    size = check_size(size)
    folder = Path(folder)
    paths = list_images(folder)
    if not paths:
        raise SasmiError(f"{folder}: no images (png, jpg, tif, npy) in it or in its images/")
    rows = [image_statistics(load_image(p, size), est) for p in paths]
    per_chip = {k: np.array([r[k] for r in rows], dtype=np.float64) for k in STATISTICS}
    result = {"folder": str(folder), "size": size, "chips": [p.name for p in paths], "per_chip": per_chip,
              "summary": {k: summarize(v) for k, v in per_chip.items()},
              "targets_found": float(np.isfinite(per_chip["shadow_length"]).mean())}
    masks = [folder / "masks" / f"{p.stem}.png" for p in paths]
    if (folder / "masks").is_dir() and all(m.is_file() for m in masks):
        truth = [mask_sizes(_load_mask(m, size)) for m in masks]
        mask_per_chip = {k: np.array([t[k] for t in truth]) for k in MASK_STATISTICS}
        result["mask_per_chip"] = mask_per_chip
        result["mask_error"] = {k: summarize(np.abs(per_chip[k] - mask_per_chip[k]))["median"]
                                for k in MASK_STATISTICS}
        has_shadow = np.isfinite(mask_per_chip["shadow_length"])
        result["targets_found_where_masked"] = float(np.isfinite(per_chip["shadow_length"])[has_shadow].mean()) \
            if has_shadow.any() else float("nan")
    return result


def median_statistics(folder: str | os.PathLike, size: int = 128) -> dict[str, float]:
    """The median of every statistic over a folder: one row of `sasmi evaluate`'s image-statistics table."""
    return {name: s["median"] for name, s in chip_statistics(folder, size=size)["summary"].items()}
