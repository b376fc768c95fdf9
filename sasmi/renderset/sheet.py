"""Contact sheets: a grid of chips, each beside its mask outline (red target, blue shadow).

Given several folders of the same scenes (a render set and its translations, say), each tile shows
the chip of each folder side by side (matched by file name), then the last one's mask outline.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from sasmi.errors import SasmiError
from sasmi.images import atomic_path, list_images, read_gray, read_usable, to_uint8
from sasmi.masks import read_mask

TARGET_RGB, SHADOW_RGB = np.array([255, 60, 60]), np.array([70, 110, 255])


def _outline(mask: np.ndarray) -> np.ndarray:
    edge = np.zeros_like(mask, dtype=bool)
    down, right = mask[1:, :] != mask[:-1, :], mask[:, 1:] != mask[:, :-1]
    edge[1:, :] |= down  # mark both pixels of a change, so each class draws its own border
    edge[:-1, :] |= down
    edge[:, 1:] |= right
    edge[:, :-1] |= right
    return edge


def tile(image01: np.ndarray, mask: np.ndarray | None, before: tuple[np.ndarray, ...] = ()) -> np.ndarray:
    """(H, (k + 2) W, 3) uint8: the k chips `before`, the chip, and the chip with the mask's class boundaries drawn."""
    grays = [np.repeat(to_uint8(image)[..., None], 3, axis=2) for image in (*before, image01)]
    if mask is None:
        return np.concatenate(grays, axis=1)
    overlay = grays[-1].copy()
    edge = _outline(mask)
    overlay[edge & (mask == 1)] = TARGET_RGB
    overlay[edge & (mask == 2)] = SHADOW_RGB
    return np.concatenate([*grays, overlay], axis=1)


def default_sheet_path(folder: str | Path) -> Path:
    """Beside the folder, not in it: a sheet inside a set of chips would be read as one of them."""
    folder = Path(folder).resolve()
    return folder.parent / f"{folder.name}_sheet.png"


def contact_sheet(folder: str | Path, out: str | Path | None = None, columns: int = 4, limit: int = 32,
                  before: tuple[str | Path, ...] = ()) -> Path:
    """Write a PNG of the first `limit` chips of `folder`, `columns` per row, each after the chips of the
    same name in the folders `before`; returns its path (default: `default_sheet_path(folder)`)."""
    if columns < 1:
        raise SasmiError(f"--columns {columns}: must be at least 1")
    if limit < 1:
        raise SasmiError(f"--limit {limit}: must be at least 1")
    folder = Path(folder)
    paths = list_images(folder)[:limit]
    if not paths:
        raise SasmiError(f"{folder}: no images to show")
    paths, images = read_usable(paths, read_gray, folder)  # an unreadable chip is skipped with a warning
    tiles = []
    for p, image in zip(paths, images):
        mask_path = folder / "masks" / (p.stem + ".png")
        tiles.append(tile(image, read_mask(mask_path) if mask_path.is_file() else None,
                          tuple(_same_chip(Path(other), p, image.shape) for other in before)))
    h, w = max(t.shape[0] for t in tiles), max(t.shape[1] for t in tiles)
    rows = -(-len(tiles) // columns)
    pad = 4
    sheet = np.full((rows * (h + pad) + pad, min(columns, len(tiles)) * (w + pad) + pad, 3), 255, dtype=np.uint8)
    for k, t in enumerate(tiles):
        r, c = divmod(k, columns)
        sheet[pad + r * (h + pad):pad + r * (h + pad) + t.shape[0], pad + c * (w + pad):pad + c * (w + pad) + t.shape[1]] = t
    out = Path(out) if out is not None else default_sheet_path(folder)
    with atomic_path(out) as tmp:
        Image.fromarray(sheet).save(tmp, format="PNG")
    return out


def _same_chip(folder: Path, chip: Path, shape: tuple[int, int]) -> np.ndarray:
    """The chip of `folder` named as `chip` (in images/ for a render set), or a SasmiError."""
    for candidate in (folder / "images" / chip.name, folder / chip.name):
        if candidate.is_file():
            image = read_gray(candidate)
            if image.shape != shape:
                raise SasmiError(f"{candidate}: {image.shape[1]}x{image.shape[0]} px, but {chip} is "
                                 f"{shape[1]}x{shape[0]}: the folders hold different chips")
            return image
    raise SasmiError(f"{folder}: has no chip {chip.name} (each folder must hold the chips of the last one)")
