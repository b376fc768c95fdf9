"""What the render knows about each pixel, as a class mask and a typed chip label.

Input: per pixel the index of the visible target and of the target shadowing it (-1 for
none), from `sasmi.render.visibility`. Output: the mask written to masks/ and the
`sasmi.labels.ChipLabel` written to labels/ (index and paths are filled in by the writer).
"""
from __future__ import annotations

import numpy as np

from sasmi.labels import ChipLabel, TargetLabel, target_geometry
from sasmi.masks import SEAFLOOR as MASK_SEAFLOOR, SHADOW as MASK_SHADOW, TARGET as MASK_TARGET
from sasmi.scene import Scene, scene_to_dict


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


def chip_label(scene: Scene, visible: np.ndarray, owner: np.ndarray, size: int, index: int = 0) -> ChipLabel:
    """The scene's sampled parameters plus, per target, its pixel centre, boxes (col0, row0, col1, row1) and geometry."""
    chip = scene.sonar.chip_size
    params = scene_to_dict(scene)
    targets = tuple(
        TargetLabel(params=t,
                    pixel_centre=((t["x"] + chip / 2) / chip * size - 0.5, (t["y"] + chip / 2) / chip * size - 0.5),
                    bbox=_bbox(visible == k), shadow_bbox=_bbox(owner == k),
                    visible_pixels=int((visible == k).sum()), shadow_pixels=int((owner == k).sum()),
                    geometry={**target_geometry(params["sonar"], t["x"], t["y"]), "heading": t["yaw"]})
        for k, t in enumerate(params.pop("targets")))
    return ChipLabel(index=index, size=size, scene=params, targets=targets)


def labels_dict(label: ChipLabel) -> dict:
    """The label as the dict `Rendered.labels` has always been: scene, targets and size, no index or paths."""
    record = label.to_json()
    for key in ("index", "image", "mask"):
        record.pop(key)
    return record
