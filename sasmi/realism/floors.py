"""Renders' targets and shadows on real seafloor chips: the real sonar's floor, the render's geometry and labels.

A render's floor is the preset's idea of the seabed, and it is what renders miss most: the real
chips that renders cover least are the ones with brighter, more textured floors, bands along
track and their own range profiles (docs/gan.md, *Real floors*). Real seafloor
chips are the plentiful part of real SAS data. Each composite keeps the render's target and
shadow as ratios to the render's own floor level, under the multiplicative speckle model, and
lays them on a real floor chip scaled to that chip's floor level. Everything else is the real
floor's seabed, under speckle moved along track so that no composite is a real chip pixel for
pixel. The geometry is the render's, so its masks and labels still hold.

A seafloor folder may mix sonars (the shared chips hold MILCO, KLSG and SASSED floors, the
target chips only MILCO). For each real target chip, the floor chip with the nearest floor
statistics (`sasmi stats`: levels, speckle, correlation, periodicity) and the next nearest are
kept (FLOOR_CHOICES), and renders draw their floors from that list. Each floor is the seabed of
one chip of that list under the speckle of another, with the slow gain swings along track that
real swaths show (`fresh_floor`).

Without real floor chips, `seabed_floor` draws a floor from real floors' statistics: a seabed and
a speckle of the real sonar's grain and gray levels (sasmi.realism.seabeds; the shipped `seabeds.pt`).
"""
from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import ndimage

from sasmi.errors import SasmiError
from sasmi.eval.config import PreservationConfig
from sasmi.images import list_images, write_gray
from sasmi.labels import ChipLabel
from sasmi.chips.stats import chip_statistics, floor_level
from sasmi.realism.display import bent
from sasmi.realism.seabeds import draw_floor, seabed_of, speckle_of
from sasmi.render.post import swing_noise

# floor-only statistics of `sasmi stats`; the target-shaped ones say nothing of a floor. far_near: seafloor chips
# may fall off less along range than target chips, and the composites (and the GAN trained on them) keep the floor's
FLOOR_STATISTICS = ("p50", "p99", "looks", "acf_range", "acf_track", "periodicity", "far_near")
FEATHER = 2          # px the target and shadow masks grow by before they are blended in
LOST = PreservationConfig()  # `sasmi evaluate`'s lost target: nothing above the blurred floor's bright percentile
VISIBLE = 1.1        # the least `_visibility` of a composite's highlight (see on_floor)
LIFTS = 4            # lifts of the highlight towards it: the blur mixes the unlifted floor into the peak
GRAIN = 1.0          # px: a render's highlight blurred by this (within the target) is its brightness, less its speckle
# floors kept per target chip: two give the composites more floors and more recall of real targets for a
# small phi cost, three more recall at twice the cost (docs/gan.md, *Why each part*; figures in docs/results.md)
FLOOR_CHOICES = 2
# gain swings along track, as a swath's gain swings from ping to ping: each floor's rows times exp(s * noise),
# s drawn in [0, BANDS], the noise of unit spread and correlated over BAND_LENGTH px. Up to 0.1 they raise recall
# of held-out targets at no phi cost; stronger or longer bands cost several times more (docs/gan.md, *Why each part*)
BANDS = 0.1
BAND_LENGTH = 8.0


def matching_floors(floors: str | os.PathLike, targets: str | os.PathLike, size: int) -> list[Path]:
    """For each chip of `targets`, the FLOOR_CHOICES chips of `floors` nearest in FLOOR_STATISTICS (repeats kept).

    Distances are in units of the target chips' interquartile range of each statistic, so
    that a statistic that varies little among the targets weighs more.
    """
    floor_stats = chip_statistics(floors, size=size)
    target_stats = chip_statistics(targets, size=size)
    f = np.stack([floor_stats["per_chip"][k] for k in FLOOR_STATISTICS], 1)   # (F, S)
    t = np.stack([target_stats["per_chip"][k] for k in FLOOR_STATISTICS], 1)  # (T, S)
    q25, q75 = np.nanpercentile(t, [25, 75], axis=0)
    scale = np.where(q75 > q25, q75 - q25, 1.0)
    distance = np.nansum(((t[:, None] - f[None]) / scale) ** 2, axis=-1)        # (T, F); NaN: no evidence
    paths = list_images(floors)  # chip_statistics' order
    nearest = np.argsort(distance, axis=1, kind="stable")[:, :FLOOR_CHOICES]  # (T, FLOOR_CHOICES)
    return [paths[i] for i in nearest.ravel()]


def _tail(image: np.ndarray, where: np.ndarray) -> float:
    """The bright percentile of the blurred image over `where`, as `sasmi evaluate` takes it."""
    return float(np.percentile(ndimage.gaussian_filter(image, LOST.smooth)[where], LOST.bright_percentile))


def _visibility(image01: np.ndarray, target: np.ndarray, floor: np.ndarray) -> float:
    """A target's blurred peak over the blurred floor's bright percentile: `sasmi evaluate` loses a target below 1."""
    blurred = ndimage.gaussian_filter(image01, LOST.smooth)
    return float(blurred[target].max() / max(np.percentile(blurred[floor], LOST.bright_percentile), 1e-6))


def _within(image: np.ndarray, where: np.ndarray, sigma: float) -> np.ndarray:
    """`image` blurred over `sigma` px from its pixels in `where` alone (normalised convolution), there; as is elsewhere."""
    blurred = ndimage.gaussian_filter(np.where(where, image, 0.0), sigma)
    weight = ndimage.gaussian_filter(where.astype(np.float64), sigma)
    return np.where(where, blurred / np.maximum(weight, 1e-9), image)


def on_floor(render01: np.ndarray, mask: np.ndarray, floor01: np.ndarray) -> np.ndarray:
    """(H, W) in [0, 1]: the render's target and shadow on a real floor chip of the same shape.

    mask (H, W) uint8: 0 seafloor, 1 target, 2 shadow (a render set's masks/).
    """
    if render01.shape != mask.shape or render01.shape != floor01.shape:
        raise SasmiError(f"on_floor: render {render01.shape}, mask {mask.shape} and floor {floor01.shape} differ")
    render, floor = render01.astype(np.float64), floor01.astype(np.float64)
    if not (mask > 0).any() or not (mask == 0).any():
        return floor.astype(np.float32)
    target = mask == 1
    ratio = render / floor_level(render, mask == 0)[None]  # the render against its own floor
    level = floor_level(floor)[None]
    laid = level * ratio                                   # the same ratios on the real floor
    if target.any():
        # a rocky real floor has a brighter tail than the render's: lift the highlight with it, as far
        # above the tail as it stood in the render (else `sasmi evaluate` counts it lost)
        lift = max(_tail(floor / level, np.ones_like(mask, bool)) / max(_tail(ratio, mask == 0), 1e-6), 1.0)
        # the highlight's brightness from the render, bent under the floor's brightest level, and its grain
        # from the floor's speckle: a render's highlight often clips to flat white, a real one is speckled
        brightness = bent(level * lift * _within(ratio, target, GRAIN), float(floor.max()))
        laid = np.where(target, brightness * speckle_of(floor), laid)
    region = ndimage.binary_dilation(mask > 0, iterations=FEATHER)
    weight = np.maximum(ndimage.gaussian_filter(region.astype(np.float64), 1.0), region)
    # bent under white (sasmi.realism.display), not clipped: a bright highlight keeps its grain
    laid_on = lambda values: np.clip((1.0 - weight) * floor + weight * bent(values, 1.0), 0.0, 1.0)
    out = laid_on(laid)
    # a faint render target (visibility under 1) that `sasmi evaluate` still finds is found
    # through the render's speckle beside it, which the real floor replaces: lifting each to
    # VISIBLE keeps it found. Each target on its own, or a dim companion beside a bright one is lost
    objects, count = ndimage.label(target)
    for k in range(1, count + 1):
        one = objects == k
        wanted = VISIBLE
        for _ in range(LIFTS):
            got = _visibility(out, one, mask == 0)
            if got >= wanted or got <= 0.0:  # a black target cannot be scaled up
                break
            laid = np.where(one, laid * wanted / got, laid)
            out = laid_on(laid)
    return out.astype(np.float32)


def gain_bands(rows: int, rng: np.random.Generator) -> np.ndarray:
    """(rows,) > 0: a gain per row along track, exp(s * noise) with s in [0, BANDS] and the noise correlated over BAND_LENGTH."""
    noise = swing_noise(rng, rows, BAND_LENGTH)
    return np.exp(rng.uniform(0.0, BANDS) * noise)


def fresh_floor(seabed01: np.ndarray, speckle01: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(H, W) in [0, 1]: the seabed of one floor chip under the speckle of another, with gain bands along track.

    A chip blurred over a few px is its seabed (patches, its range profile; `seabed_of`); the chip over
    that seabed is its speckle, which the multiplicative model makes independent of the seabed. The
    speckle moves along track by a quarter to three quarters of the chip, wrapping round: without
    it every composite is its floor chip pixel for pixel outside the target, which `sasmi
    evaluate`'s copying detector flags. Another matched chip's speckle also brings the composites
    nearer held-out real chips, and the gain bands (`gain_bands`) reach chips the floor chips alone
    do not (docs/gan.md, *Real floors*).
    """
    if seabed01.shape != speckle01.shape:
        raise SasmiError(f"fresh_floor: seabed chip {seabed01.shape} and speckle chip {speckle01.shape} differ")
    speckle = speckle_of(speckle01)
    shift = int(rng.integers(speckle.shape[0] // 4, 3 * speckle.shape[0] // 4 + 1))
    seabed = seabed_of(seabed01) * gain_bands(seabed01.shape[0], rng)[:, None]
    return np.clip(seabed * np.roll(speckle, shift, axis=0), 0.0, 1.0).astype(np.float32)


def seabed_floor(seabeds, shape: tuple[int, int], seed: int, index: int) -> np.ndarray:
    """`shape` in [0, 1]: chip `index`'s floor, drawn from `seabeds` (sasmi.realism.seabeds.draw_floor) from a
    stream seeded by (seed, index) alone. Nothing of the render but its shape: its speckle, which no real sonar
    made, is replaced as a real floor chip replaces it. No gain bands: a drawn seabed keeps its source's swings
    along track, and bands on top swing half as much again as real target chips do (`sasmi stats`)."""
    floor = draw_floor(seabeds, shape, np.random.default_rng([seed, index]))
    return np.clip(floor, 0.0, 1.0).astype(np.float32)


def seabed_floor_label(label: ChipLabel, seabeds, seed: int, index: int) -> ChipLabel:
    """A render's label for its composite on `seabed_floor`: the geometry holds, the rendered floor's rocks are
    gone with its speckle (as on a real floor chip, `floor_label`), and the seabeds file and the stream are recorded."""
    floor = {"seabeds": seabeds.path and str(seabeds.path), "seabed_stream": [seed, index]}
    return replace(label, clutter=(), extra={**label.extra, "floor": floor})


def _draw(choices: list[Path], seed: int, index: int) -> tuple[np.random.Generator, Path, Path, bool]:
    """Chip `index`'s floor chips (seabed, speckle), whether the seabed is flipped, and the stream that goes on."""
    rng = np.random.default_rng([seed, index])
    seabed, speckle = (choices[i] for i in rng.integers(len(choices), size=2))
    return rng, seabed, speckle, bool(rng.random() < 0.5)


def floor_for(choices: list[Path], seed: int, index: int, size: int) -> np.ndarray:
    """(size, size) in [0, 1]: chip `index`'s floor, the seabed of one chip of `choices` (flipped up-down
    half the time: along track has no direction) under the speckle of another (`fresh_floor`), from a
    stream seeded by (seed, index) alone: the same in any batch."""
    from sasmi.preprocess import load_image

    rng, seabed, speckle, flipped = _draw(choices, seed, index)
    seabed_chip, speckle_chip = load_image(seabed, size), load_image(speckle, size)
    if flipped:
        seabed_chip = seabed_chip[::-1]
    return fresh_floor(seabed_chip, speckle_chip, rng)


def floor_label(label: ChipLabel, choices: list[Path], seed: int, index: int) -> ChipLabel:
    """A render's label for its composite on `floor_for(choices, seed, index)`: the geometry holds, but the
    rendered floor's rocks are gone (the composite keeps only the target and shadow masks), so its clutter goes,
    and which real chips made the floor is recorded. `seafloor` and `post` still say how the render was drawn."""
    _, seabed, speckle, flipped = _draw(choices, seed, index)
    floor = {"seabed": str(seabed), "speckle": str(speckle), "seabed_flipped": flipped}
    return replace(label, clutter=(), extra={**label.extra, "floor": floor})


def onto_real_floors(renders: str | os.PathLike, floors: str | os.PathLike, targets: str | os.PathLike,
                     out: str | os.PathLike, size: int, seed: int = 0) -> int:
    """Write every chip of the render set `renders` on a real floor into `out` (a render set, labels carried).

    Chip i (the i-th image) takes `floor_for(matching_floors(floors, targets), seed, i)`, as
    `sasmi generate --floors` does for scene i; returns the count.
    """
    if not list_images(floors):
        raise SasmiError(f"--floors {floors}: no image (png, jpg, tif, tiff, npy) in it")
    choices = matching_floors(floors, targets, size)
    return onto_floors(renders, out, size, lambda i: floor_for(choices, seed, i, size),
                       lambda label, i: floor_label(label, choices, seed, i))


def onto_seabed_floors(renders: str | os.PathLike, seabeds, out: str | os.PathLike, size: int, seed: int = 0) -> int:
    """`onto_real_floors` with `seabed_floor`s, as `sasmi generate` lays renders with the shipped generator."""
    return onto_floors(renders, out, size, lambda i: seabed_floor(seabeds, (size, size), seed, i),
                       lambda label, i: seabed_floor_label(label, seabeds, seed, i))


def onto_floors(renders: str | os.PathLike, out: str | os.PathLike, size: int, floor_of, relabel) -> int:
    """Chip i of the render set `renders` on the floor `floor_of(i)`, into the render set `out`."""
    from sasmi.gan.translate import carry_labels
    from sasmi.masks import read_mask
    from sasmi.preprocess import load_image

    renders, out = Path(renders), Path(out)
    paths = list_images(renders / "images")
    if not paths or not (renders / "masks").is_dir():
        raise SasmiError(f"{renders}: not a render set (images/ and masks/)")
    for index, path in enumerate(paths):
        render = load_image(path, size)
        mask = read_mask(renders / "masks" / f"{path.stem}.png")
        if mask.shape != render.shape:
            raise SasmiError(f"{renders / 'masks' / path.stem}.png: mask {mask.shape} against image {render.shape}")
        write_gray(out / "images" / f"{path.stem}.png", on_floor(render, mask, floor_of(index)))
    position = {path.stem: index for index, path in enumerate(paths)}  # chip i's floor is floor_of(i)
    carry_labels(renders, out, lambda label: relabel(label, position[Path(label.image).stem]))
    return len(paths)


class FloorsAhead:
    """floor_of(i) for the chips of `order`, drawn on a thread: draw_after(i) starts the `ahead` chips after chip i,
    to be drawn while the next chips render. numpy's FFTs and sorts, most of a drawn floor's time, release the GIL,
    and the render leaves core time idle where the generator leaves none. The same floors as floor_of(i) called
    here; a chip not drawn ahead is drawn here, and one drawn ahead but never asked for is dropped once `ahead`
    chips behind (a resumed run skips the chips it has)."""

    def __init__(self, floor_of, order: list[int], ahead: int):
        from concurrent.futures import ThreadPoolExecutor

        self._floor_of, self._order, self._ahead = floor_of, list(order), ahead
        self._position = {index: k for k, index in enumerate(self._order)}
        self._submitted = 0  # the chips of `order` before this position have been started
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="floors")
        self._pending: dict = {}  # index -> Future

    def __call__(self, index: int) -> np.ndarray:
        future = self._pending.pop(index, None)
        return future.result() if future is not None else self._floor_of(index)

    def draw_after(self, index: int) -> None:
        """Start drawing the `ahead` chips after `index` in the order (those not started yet)."""
        at = self._position.get(index)
        if at is None:
            return
        for behind in [i for i in self._pending if self._position[i] < at - self._ahead]:
            self._pending.pop(behind).cancel()
        for i in self._order[max(self._submitted, at + 1):at + 1 + self._ahead]:
            self._pending[i] = self._pool.submit(self._floor_of, i)
        self._submitted = max(self._submitted, at + 1 + self._ahead)

    def close(self) -> None:
        for future in self._pending.values():
            future.cancel()
        self._pool.shutdown(wait=True)
