"""Does translation keep the scene? Target preservation measured on labelled image sets.

On each image of a set that carries the render's masks and labels (a render set, or a
translated render set) it measures whether the target is still where the label says:
the overlap of the image's dark region with the labelled acoustic shadow, and the
distance from the bright-highlight centroid to the labelled target centre. On the renders
themselves the same numbers give the baseline a translation should keep. Definitions in
`measure_image` and docs/evaluate.md. Labels are read only through sasmi.labels.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.eval.config import PreservationConfig
from sasmi.eval.report import MASK_SEAFLOOR, MASK_SHADOW, MASK_TARGET, Report, Section, examples_figure, \
    preservation_markdown
from sasmi.images import list_images, read_gray
from sasmi.masks import read_mask
from sasmi.labels import Box, TargetLabel, has_labels, labels_by_index


def _window(shape: tuple[int, int], boxes: Sequence[Box | None], margin: int) -> np.ndarray:
    """Boolean (H, W): union of the boxes (col0, row0, col1, row1; end exclusive) grown by margin."""
    out = np.zeros(shape, dtype=bool)
    for box in boxes:
        if box is None:
            continue
        c0, r0, c1, r1 = (int(round(v)) for v in box)
        out[max(r0 - margin, 0):min(r1 + margin, shape[0]), max(c0 - margin, 0):min(c1 + margin, shape[1])] = True
    return out


def _target_box(target: TargetLabel) -> Box:
    # a target hidden from the camera (no bbox) is searched for around its labelled centre
    if target.bbox is not None:
        return target.bbox
    c, r = target.pixel_centre
    return (c, r, c + 1, r + 1)


def measure_image(image01: np.ndarray, mask: np.ndarray, targets: Sequence[TargetLabel],
                  cfg: PreservationConfig = PreservationConfig()) -> dict:
    """Shadow IoU, highlight centroid errors and target contrast of one labelled image.

    image01 (H, W) in [0, 1]; mask (H, W) uint8 (0 seafloor, 1 target, 2 shadow) and
    targets in this image's pixels. With s the image blurred by `smooth` px and floor the
    s values where mask == 0:
    - dark = s < dark_fraction · median(floor), inside the targets' and shadows' boxes
      grown by `margin`; shadow_iou = |dark ∩ shadow| / |dark ∪ shadow| (NaN without shadow).
    - per target, the highlight weight w = max(s − percentile(floor, bright_percentile), 0)
      inside its box grown by `margin`; its centroid Σ w·(col, row) / Σ w; the error is
      the distance in px to the label's pixel_centre (NaN and `lost` when w is all 0).
    - target_contrast = mean(s over mask == 1) / median(floor) (NaN without target pixels).
    """
    from scipy.ndimage import gaussian_filter

    s = gaussian_filter(image01.astype(np.float64), cfg.smooth)
    floor = s[mask == MASK_SEAFLOOR]
    if floor.size == 0:
        raise SasmiError("measure_image: the mask has no seafloor pixels to compare with")
    level = max(float(np.median(floor)), 1e-6)
    shadow = mask == MASK_SHADOW
    near = _window(s.shape, [b for t in targets for b in (_target_box(t), t.shadow_bbox)], cfg.margin)
    dark = (s < cfg.dark_fraction * level) & (near | shadow)
    union = (dark | shadow).sum()
    iou = float((dark & shadow).sum() / union) if shadow.any() else math.nan

    bright = np.clip(s - np.percentile(floor, cfg.bright_percentile), 0.0, None)
    rows, cols = np.indices(s.shape)
    centroids, errors = [], []
    for t in targets:
        w = bright * _window(s.shape, [_target_box(t)], cfg.margin)
        if w.sum() == 0:
            centroids.append(None)
            errors.append(math.nan)
            continue
        c, r = float((w * cols).sum() / w.sum()), float((w * rows).sum() / w.sum())
        centroids.append([c, r])
        errors.append(math.hypot(c - t.pixel_centre[0], r - t.pixel_centre[1]))
    target_px = mask == MASK_TARGET
    contrast = float(s[target_px].mean() / level) if target_px.any() else math.nan
    return {"shadow_iou": iou, "centroid_errors": errors, "centroids": centroids, "target_contrast": contrast,
            "dark": dark}


def summarise(measures: Sequence[dict]) -> dict:
    """Medians over images (over targets for the centroid error) and the fraction of targets lost."""
    def median(values):
        values = [v for v in values if math.isfinite(v)]
        return float(np.median(values)) if values else math.nan

    errors = [e for m in measures for e in m["centroid_errors"]]
    return {"images": len(measures), "targets": len(errors),
            "shadow_iou": median([m["shadow_iou"] for m in measures]),
            "centroid_error_px": median(errors),
            "lost": float(np.mean([not math.isfinite(e) for e in errors])) if errors else math.nan,
            "target_contrast": median([m["target_contrast"] for m in measures])}


def load_labelled(folder: str | os.PathLike) -> list[tuple[Path, np.ndarray, np.ndarray, tuple[TargetLabel, ...]]]:
    """(image path, image (H, W) in [0, 1], mask (H, W) uint8, targets) for every labelled image.

    Images are matched to masks/<stem>.png and to the label whose index is int(stem). A
    translated image of another size than its render gets its mask (nearest) and labels
    rescaled to it.
    """
    folder = Path(folder)
    labels = labels_by_index(folder)
    out = []
    for path in list_images(folder):
        mask_path = folder / "masks" / f"{path.stem}.png"
        if not (path.stem.isdigit() and int(path.stem) in labels and mask_path.is_file()):
            continue
        image = read_gray(path)
        mask_image = Image.fromarray(read_mask(mask_path))  # ids, never palette colours
        targets = labels[int(path.stem)].targets
        if mask_image.size != (image.shape[1], image.shape[0]):
            scale = image.shape[1] / mask_image.size[0]
            targets = tuple(t.scaled(scale) for t in targets)
            mask_image = mask_image.resize((image.shape[1], image.shape[0]), Image.Resampling.NEAREST)
        out.append((path, image, np.asarray(mask_image, dtype=np.uint8), targets))
    return out


def target_preservation(sets: dict[str, Path], out_dir: str | os.PathLike,
                        cfg: PreservationConfig = PreservationConfig()) -> Report:
    """Measure every set that has masks/ and labels.jsonl; the others are listed as skipped."""
    out_dir = Path(out_dir)
    labelled = {name: folder for name, folder in sets.items() if has_labels(folder)}
    metrics = {}
    for name, folder in labelled.items():
        items = load_labelled(folder)
        if not items:
            raise SasmiError(f"{folder}: has masks/ and labels.jsonl but no image matches them by number")
        measures = [measure_image(image, mask, targets, cfg)
                    for _, image, mask, targets in tqdm(items, desc=f"preservation {name}", leave=False, disable=None)]
        metrics[name] = summarise(measures)
        examples_figure(items[:cfg.examples], measures[:cfg.examples], out_dir / f"preservation_{name}.png")
    skipped = [name for name in sets if name not in labelled]
    return Report({"target_preservation": metrics},
                  (Section("Target preservation", preservation_markdown(metrics, skipped, cfg)),))
