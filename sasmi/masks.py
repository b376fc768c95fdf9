"""Label masks on disk: palette PNGs that an image viewer shows in colour and every reader sees as ids.

A render set holds three masks per chip, all (H, W) uint8:
- `masks/NNNNNN.png`: the class mask, 0 seafloor, 1 target, 2 acoustic shadow;
- `instances/NNNNNN.png`: 0 background, k + 1 where target k (its index in the label's
  `targets`) is visible;
- `shadows/NNNNNN.png`: 0 background, k + 1 where target k casts its acoustic shadow, so
  each shadow is linked to its target by id.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image

from sasmi.errors import SasmiError
from sasmi.images import atomic_path

SEAFLOOR, TARGET, SHADOW = 0, 1, 2
CLASS_COLOURS = [(40, 40, 40), (230, 60, 40), (40, 110, 230)]  # seafloor, target, shadow


def _palette(colours: list[tuple[int, int, int]]) -> list[int]:
    flat = [c for rgb in colours for c in rgb]
    return flat + [0] * (768 - len(flat))


def _instance_colours() -> list[tuple[int, int, int]]:
    # id 0 dark; ids 1..255 spread around the hue circle so neighbouring ids differ
    import colorsys

    colours = [(0, 0, 0)]
    for i in range(1, 256):
        r, g, b = colorsys.hsv_to_rgb((i * 0.61803398875) % 1.0, 0.75, 1.0)
        colours.append((int(r * 255), int(g * 255), int(b * 255)))
    return colours


_CLASS_PALETTE = _palette(CLASS_COLOURS)
_INSTANCE_PALETTE = _palette(_instance_colours())


def _write_palette_png(path: str | os.PathLike, ids: np.ndarray, palette: list[int]) -> None:
    if ids.ndim != 2:
        raise ValueError(f"expected an (H, W) mask, got shape {ids.shape}")
    if ids.size and (ids.min() < 0 or ids.max() > 255):
        raise ValueError("mask ids must lie in [0, 255]")
    image = Image.fromarray(ids.astype(np.uint8), mode="P")
    image.putpalette(palette)
    with atomic_path(path) as tmp:
        image.save(tmp, format="PNG")


def write_class_mask(path: str | os.PathLike, mask: np.ndarray) -> None:
    """(H, W) ids 0 seafloor, 1 target, 2 shadow."""
    _write_palette_png(path, mask, _CLASS_PALETTE)


def write_instance_mask(path: str | os.PathLike, ids: np.ndarray) -> None:
    """(H, W) ids: 0 background, k + 1 for target k (at most 255 targets in a chip)."""
    _write_palette_png(path, ids, _INSTANCE_PALETTE)


def instance_ids(owner: np.ndarray) -> np.ndarray:
    """A per-pixel target index (-1 where none) -> instance ids (0 background, k + 1 for target k)."""
    if owner.size and owner.max() >= 255:
        raise SasmiError(f"a chip holds {int(owner.max()) + 1} targets; instance masks hold at most 254")
    return (owner.astype(np.int32) + 1).clip(0, 255).astype(np.uint8)


def read_mask(path: str | os.PathLike) -> np.ndarray:
    """Any mask PNG (palette or plain gray) -> (H, W) uint8 ids, never colours."""
    path = Path(path)
    try:
        with Image.open(path) as im:
            if im.mode not in ("P", "L"):
                raise SasmiError(f"{path}: a mask must be a palette or 8-bit gray PNG, not mode {im.mode}")
            return np.asarray(im, dtype=np.uint8).copy()
    except (OSError, ValueError) as e:
        raise SasmiError(f"{path}: cannot read mask ({e})") from None
