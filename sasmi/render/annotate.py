"""What the render knows about each pixel, as a class mask and a typed chip label.

Input: per pixel the index of the visible target and of the target shadowing it (-1 for
none), from `sasmi.render.visibility`. Output: the mask written to masks/ and the
`sasmi.labels.ChipLabel` written to labels/ (index and paths are filled in by the writer).
"""
from __future__ import annotations

import math

import numpy as np

from sasmi.labels import ChipLabel, TargetLabel, target_geometry
from sasmi.masks import SEAFLOOR as MASK_SEAFLOOR, SHADOW as MASK_SHADOW, TARGET as MASK_TARGET
from sasmi.render.seafloor import rocks
from sasmi.scene.model import Scene, scene_to_dict


ROCK_EXTENT = 3.0  # sigmas of a rock's Gaussian bump that its clutter box spans


def class_mask(visible: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """(H, W) uint8: 0 seafloor, 1 target, 2 acoustic shadow (a seen target wins over shadow)."""
    mask = np.full(visible.shape, MASK_SEAFLOOR, dtype=np.uint8)
    mask[owner >= 0] = MASK_SHADOW
    mask[visible >= 0] = MASK_TARGET
    return mask


def _bbox(pixels: np.ndarray) -> tuple[int, int, int, int] | None:
    rows, cols = np.nonzero(pixels)
    if len(rows) == 0:
        return None
    return int(cols.min()), int(rows.min()), int(cols.max()) + 1, int(rows.max()) + 1


def chip_label(scene: Scene, visible: np.ndarray, owner: np.ndarray, size: int, index: int = 0,
               floor_rocks: tuple[tuple[float, float, float], ...] | None = None) -> ChipLabel:
    """The scene's sampled parameters plus, per target, its pixel centre, boxes (col0, row0, col1, row1) and geometry;
    `floor_rocks`: the floor's, when the caller has drawn them (`clutter_labels`)."""
    chip = scene.sonar.chip_size
    params = scene_to_dict(scene)
    targets = tuple(
        TargetLabel(params=t,
                    pixel_centre=((t["x"] + chip / 2) / chip * size - 0.5, (t["y"] + chip / 2) / chip * size - 0.5),
                    bbox=_bbox(visible == k), shadow_bbox=_bbox(owner == k),
                    visible_pixels=int((visible == k).sum()), shadow_pixels=int((owner == k).sum()),
                    geometry={**target_geometry(params["sonar"], t["x"], t["y"]), "heading": t["yaw"]})
        for k, t in enumerate(params.pop("targets")))
    return ChipLabel(index=index, size=size, scene=params, targets=targets,
                     clutter=clutter_labels(scene, size, floor_rocks))


def clutter_labels(scene: Scene, size: int, floor_rocks: tuple[tuple[float, float, float], ...] | None = None
                   ) -> tuple[dict, ...]:
    """One record per rock: pixel centre (col, row), radius (px) and box (col0, row0, col1, row1), clipped to the chip.

    A rock is a Gaussian bump of height r and sigma r / 2 (sasmi.render.seafloor). Its label
    radius is ROCK_EXTENT sigmas: there the bump is 1 % of its height, but its slope (0.07)
    still brightens the floor by a third at a 10 deg grazing angle; at r (2 sigma) the slope
    is 0.5 and the facet turned towards the track is among the brightest pixels of the chip.
    The box holds the raised pixels and the bright facet; the rock's shadow is not in it.
    `floor_rocks`: the rocks (x, y, radius in m) of the scene's floor, when it was made (drawing them alone costs a
    millisecond: its rough surface's noise comes first).
    """
    chip = scene.sonar.chip_size
    per_metre = size / chip
    out = []
    for x, y, r in rocks(scene.seafloor, chip, scene.seed) if floor_rocks is None else floor_rocks:
        col, row = (x + chip / 2) * per_metre - 0.5, (y + chip / 2) * per_metre - 0.5
        radius = ROCK_EXTENT * r / 2 * per_metre
        box = (max(0, math.floor(col + 0.5 - radius)), max(0, math.floor(row + 0.5 - radius)),
               min(size, math.ceil(col + 0.5 + radius)), min(size, math.ceil(row + 0.5 + radius)))
        out.append({"kind": "rock", "pixel_centre": [col, row], "radius": radius, "bbox": list(box),
                    "x": x, "y": y, "radius_m": r})
    return tuple(out)


def clutter_in_slant(clutter: tuple[dict, ...], column, size: int, unit: float) -> tuple[dict, ...]:
    """`clutter` of a slant-range chip: centre and box columns moved by `column` (ground x, height in
    chip units -> slant column, `sasmi.render.slant.SlantMap.column`; `unit` chip units per metre).

    A rock's top lies over towards the track (it is nearer in slant range than its base), so
    the box's near edge is taken at the rock's height; the radius stays the along-track one.
    """
    def ground(u: float) -> float:  # continuous pixel coordinate (0 = left edge) -> chip units
        return u / size * 2 - 1

    out = []
    for c in clutter:
        c0, r0, c1, r1 = c["bbox"]
        col = float(column(ground(c["pixel_centre"][0] + 0.5), 0.0))
        near = float(column(ground(c0), c["radius_m"] * unit)) + 0.5
        far = float(column(ground(c1), 0.0)) + 0.5
        box = [max(0, math.floor(near)), r0, min(size, math.ceil(far)), r1]
        out.append({**c, "pixel_centre": [col, c["pixel_centre"][1]], "bbox": box})
    return tuple(out)


def labels_dict(label: ChipLabel) -> dict:
    """The label as the dict `Rendered.labels` holds: scene, targets and size, no index or paths."""
    record = label.to_json()
    for key in ("index", "image", "mask"):
        record.pop(key)
    return record
