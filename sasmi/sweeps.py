"""Does translation keep the scene? Target preservation on labelled sets, and pose sweeps.

Target preservation measures, on each image of a set that carries the render's masks
and labels (a render set, or a translated render set), whether the target is still
where the label says: the overlap of the image's dark region with the labelled acoustic
shadow, and the distance from the bright-highlight centroid to the labelled target
centre. Measured on the renders themselves the same numbers give the baseline that a
translation should keep. Definitions in `measure_image` and docs/evaluate.md.

A pose sweep takes one target of a preset, moves it along the chip diagonal and turns
it through 0–180°, renders each pose, translates it, and shows both as grids with the
same measurements per pose. Only `pose_sweep_from_runs` touches Mitsuba and the
generator (imported inside it), so everything else runs without them.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
from PIL import Image
from tqdm import tqdm

from sasmi.dataset import read_labels as read_records
from sasmi.errors import SasmiError
from sasmi.evaluate import Report, Section, save_figure
from sasmi.images import list_images, read_gray

MASK_SEAFLOOR, MASK_TARGET, MASK_SHADOW = 0, 1, 2  # as written by sasmi.mitsuba_render


@dataclass(frozen=True)
class PreservationConfig:
    margin: int = 8  # px searched around the labelled target and shadow: a shift of a few px is measured, not missed
    smooth: float = 1.5  # px, Gaussian blur before thresholding: speckle changes from pixel to pixel
    dark_fraction: float = 0.5  # "dark" = below this fraction of the median seafloor (mask 0) level
    bright_percentile: float = 99.0  # "bright" = above this percentile of the seafloor level
    examples: int = 6  # images drawn with their measurements per set


@dataclass(frozen=True)
class SweepConfig:
    steps: int = 7  # poses per sweep (grid columns)
    reach: float = 0.5  # the diagonal runs from −reach to +reach of the half chip in x and y
    seed: int = 0  # preset draw used as the base scene (its first target is swept)
    spp: int = 64  # samples per pixel of the sweep renders
    batch: int = 8  # generator batch


# ---------------------------------------------------------------------------------------
# Measurements on one image
# ---------------------------------------------------------------------------------------

def _window(shape: tuple[int, int], boxes: Sequence[Sequence[float] | None], margin: int) -> np.ndarray:
    """Boolean (H, W): union of the boxes (col0, row0, col1, row1; end exclusive) grown by margin."""
    out = np.zeros(shape, dtype=bool)
    for box in boxes:
        if box is None:
            continue
        c0, r0, c1, r1 = (int(round(v)) for v in box)
        out[max(r0 - margin, 0):min(r1 + margin, shape[0]), max(c0 - margin, 0):min(c1 + margin, shape[1])] = True
    return out


def _centre_box(target: dict) -> list[float]:
    # a target hidden from the camera (no bbox) is searched for around its labelled centre
    c, r = target["pixel_centre"]
    return [c, r, c + 1, r + 1]


def measure_image(image01: np.ndarray, mask: np.ndarray, targets: Sequence[dict],
                  cfg: PreservationConfig = PreservationConfig()) -> dict:
    """Shadow IoU, highlight centroid errors and target contrast of one labelled image.

    image01 (H, W) in [0, 1]; mask (H, W) uint8 (0 seafloor, 1 target, 2 shadow) and
    targets (label dicts with pixel_centre, bbox, shadow_bbox) in this image's pixels.
    With s the image blurred by `smooth` px and floor the s values where mask == 0:
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
    near = _window(s.shape, [b for t in targets for b in (t.get("bbox") or _centre_box(t), t.get("shadow_bbox"))],
                   cfg.margin)
    dark = (s < cfg.dark_fraction * level) & (near | shadow)
    union = (dark | shadow).sum()
    iou = float((dark & shadow).sum() / union) if shadow.any() else math.nan

    bright = np.clip(s - np.percentile(floor, cfg.bright_percentile), 0.0, None)
    rows, cols = np.indices(s.shape)
    centroids, errors = [], []
    for t in targets:
        w = bright * _window(s.shape, [t.get("bbox") or _centre_box(t)], cfg.margin)
        if w.sum() == 0:
            centroids.append(None)
            errors.append(math.nan)
            continue
        c, r = float((w * cols).sum() / w.sum()), float((w * rows).sum() / w.sum())
        centroids.append([c, r])
        errors.append(math.hypot(c - t["pixel_centre"][0], r - t["pixel_centre"][1]))
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


# ---------------------------------------------------------------------------------------
# Labelled sets on disk
# ---------------------------------------------------------------------------------------

def has_labels(folder: str | os.PathLike) -> bool:
    folder = Path(folder)
    return (folder / "masks").is_dir() and (folder / "labels.jsonl").is_file()


def read_labels(folder: str | os.PathLike) -> dict[int, list[dict]]:
    """labels.jsonl → {index: targets}; a malformed line is a SasmiError naming it."""
    out = {}
    for n, record in enumerate(read_records(folder), start=1):
        try:
            out[int(record["index"])] = list(record["targets"])
        except (ValueError, KeyError, TypeError) as e:
            raise SasmiError(f"{Path(folder) / 'labels.jsonl'}: record {n} has no valid 'index' and 'targets' ({e})") from None
    return out


def _scaled(targets: Sequence[dict], scale: float) -> list[dict]:
    """Labels in render pixels → labels in the pixels of an image `scale` times as large."""
    def box(b):
        return None if b is None else [v * scale for v in b]

    return [{**t, "pixel_centre": [(v + 0.5) * scale - 0.5 for v in t["pixel_centre"]],
             "bbox": box(t.get("bbox")), "shadow_bbox": box(t.get("shadow_bbox"))} for t in targets]


def load_labelled(folder: str | os.PathLike) -> list[tuple[Path, np.ndarray, np.ndarray, list[dict]]]:
    """(image path, image (H, W) in [0, 1], mask (H, W) uint8, targets) for every labelled image.

    Images are matched to masks/<stem>.png and to the label whose index is int(stem). A
    translated image of another size than its render gets its mask (nearest) and labels
    rescaled to it.
    """
    folder = Path(folder)
    labels = read_labels(folder)
    out = []
    for path in list_images(folder):
        mask_path = folder / "masks" / f"{path.stem}.png"
        if not (path.stem.isdigit() and int(path.stem) in labels and mask_path.is_file()):
            continue
        image = read_gray(path)
        with Image.open(mask_path) as m:
            mask_image = m.convert("L") if m.mode != "L" else m.copy()
        targets = labels[int(path.stem)]
        if mask_image.size != (image.shape[1], image.shape[0]):
            targets = _scaled(targets, image.shape[1] / mask_image.size[0])
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
        _examples_figure(items[:cfg.examples], measures[:cfg.examples], out_dir / f"preservation_{name}.png")
    skipped = [name for name in sets if name not in labelled]
    return Report({"target_preservation": metrics},
                  (Section("Target preservation", _preservation_markdown(metrics, skipped, cfg)),))


def _preservation_markdown(metrics: dict, skipped: list[str], cfg: PreservationConfig) -> str:
    lines = ["Measured on every set that carries a render's masks/ and labels.jsonl (a render set, or a "
             "translated render set). Compare a translated set with its render set: a translation that keeps "
             "the scene keeps these numbers.", ""]
    if metrics:
        lines += ["| set | images | shadow IoU | highlight centroid error (px) | targets lost | target contrast |",
                  "|---|---:|---:|---:|---:|---:|"]
        for name, m in metrics.items():
            lines.append(f"| {name} | {m['images']} | {m['shadow_iou']:.2f} | {m['centroid_error_px']:.1f} | "
                         f"{100 * m['lost']:.0f} % | {m['target_contrast']:.2f} |")
        lines += ["", "Medians over images (over targets for the centroid error). Definitions, with the image "
                  f"blurred by a Gaussian of σ = {cfg.smooth:g} px and *floor* its values where the mask says "
                  "seafloor:",
                  f"- **shadow IoU**: dark pixels (below {cfg.dark_fraction:g} × median floor) within "
                  f"{cfg.margin} px of the labelled target and shadow boxes, intersection over union with the "
                  "labelled shadow mask.",
                  f"- **highlight centroid error**: centroid of the brightness above the floor's "
                  f"{cfg.bright_percentile:g}th percentile within {cfg.margin} px of the target's box, distance "
                  "to the label's pixel_centre. The highlight is the sonar-facing side, so even a render is a "
                  "few px off: compare with the render set.",
                  "- **targets lost**: targets with nothing brighter than that percentile near them.",
                  "- **target contrast**: mean over the labelled target pixels / median floor.", ""]
        lines += [f"![preservation examples: {name}](preservation_{name}.png)" for name in metrics]
        lines += ["", "Examples: labelled shadow outlined in cyan, measured dark region in red, label centre as a "
                  "green +, highlight centroid as a red ×."]
    if skipped:
        lines += ["", f"Skipped (no masks/ and labels.jsonl): {', '.join(skipped)}."]
    return "\n".join(lines)


def _examples_figure(items: Sequence[tuple], measures: Sequence[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2.2 * len(items), 2.5))
    for ax, (image_path, image, mask, targets), m in zip(fig.subplots(1, len(items), squeeze=False)[0], items, measures):
        _draw_measured(ax, image, mask, targets, m, f"{image_path.stem}  IoU {m['shadow_iou']:.2f}")
    save_figure(fig, path)


def _draw_measured(ax, image: np.ndarray, mask: np.ndarray, targets: Sequence[dict], m: dict, title: str) -> None:
    ax.imshow(image, cmap="gray", vmin=0, vmax=1)
    if (mask == MASK_SHADOW).any():
        ax.contour(mask == MASK_SHADOW, levels=[0.5], colors="cyan", linewidths=0.8)
    if m["dark"].any():
        ax.contour(m["dark"], levels=[0.5], colors="red", linewidths=0.6)
    for t, c in zip(targets, m["centroids"]):
        ax.plot(*t["pixel_centre"], "+", color="lime", markersize=8)
        if c is not None:
            ax.plot(*c, "x", color="red", markersize=6)
    ax.set_title(title, fontsize=7)
    ax.set_axis_off()


# ---------------------------------------------------------------------------------------
# Pose sweeps
# ---------------------------------------------------------------------------------------

def pose_scenes(scene, cfg: SweepConfig = SweepConfig()) -> tuple[list, list]:
    """Scenes with only the first target: moved along the diagonal, and turned through 0–180°."""
    if not scene.targets:
        raise SasmiError("pose sweep: the preset's scene has no target to sweep")
    target = scene.targets[0]
    half = scene.sonar.chip_size / 2
    offsets = np.linspace(-cfg.reach, cfg.reach, cfg.steps) * half
    moved = [dataclasses.replace(scene, targets=(dataclasses.replace(target, x=float(o), y=float(o)),))
             for o in offsets]
    turned = [dataclasses.replace(scene, targets=(dataclasses.replace(target, yaw=float(a)),))
              for a in np.linspace(0.0, 180.0, cfg.steps)]
    return moved, turned


def pose_sweep(scene, render: Callable, translate: Callable[[np.ndarray], np.ndarray], out_dir: str | os.PathLike,
               cfg: SweepConfig = SweepConfig(), measure_cfg: PreservationConfig = PreservationConfig()) -> Report:
    """Render and translate both sweeps of `scene`; grids and per-pose measurements.

    render(scene) → an object with .image (H, W) in [0, 1], .mask (H, W) uint8 and
    .labels["targets"]; translate((N, H, W) in [0, 1]) → (N, H, W) in [0, 1].
    """
    out_dir = Path(out_dir)
    moved, turned = pose_scenes(scene, cfg)
    metrics, lines = {}, ["One target of the preset, moved along the chip diagonal (top) and turned through "
                          "0–180° (bottom); in each grid renders above, their translations below. Per pose: "
                          "highlight centroid error (px) and shadow IoU of the render → the translation "
                          "(definitions under Target preservation).", ""]
    for name, scenes, caption in (("translation", moved, lambda t: f"x = y = {t.x:+.2f} m"),
                                  ("rotation", turned, lambda t: f"yaw {t.yaw:.0f}°")):
        rendered = [render(s) for s in tqdm(scenes, desc=f"render {name} sweep", leave=False, disable=None)]
        images = np.stack([r.image for r in rendered])  # (steps, H, W) in [0, 1]
        translated = translate(images)
        assert translated.shape == images.shape, (translated.shape, images.shape)
        poses = []
        for s, r, out in zip(scenes, rendered, translated):
            before = measure_image(r.image, r.mask, r.labels["targets"], measure_cfg)
            after = measure_image(out, r.mask, r.labels["targets"], measure_cfg)
            t = s.targets[0]
            poses.append({"x": t.x, "y": t.y, "yaw": t.yaw, "caption": caption(t),
                          "render": _pose_numbers(before), "translated": _pose_numbers(after),
                          "measures": (before, after)})
        _sweep_grid(rendered, translated, poses, out_dir / f"sweep_{name}.png")
        metrics[name] = [{k: v for k, v in p.items() if k not in ("caption", "measures")} for p in poses]
        lines += [f"![{name} sweep](sweep_{name}.png)", ""]
    return Report({"pose_sweep": metrics}, (Section("Pose sweeps", "\n".join(lines)),))


def _pose_numbers(m: dict) -> dict:
    return {"centroid_error_px": m["centroid_errors"][0], "shadow_iou": m["shadow_iou"],
            "target_contrast": m["target_contrast"]}


def _sweep_grid(rendered: Sequence, translated: np.ndarray, poses: Sequence[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1.9 * len(poses), 4.2))
    axes = fig.subplots(2, len(poses), squeeze=False)
    for col, (r, out, p) in enumerate(zip(rendered, translated, poses)):
        for row, (image, key) in enumerate(((r.image, "render"), (out, "translated"))):
            n = p[key]
            _draw_measured(axes[row, col], image, r.mask, r.labels["targets"], p["measures"][row],
                           f"{p['caption'] if row == 0 else key}\nerr {n['centroid_error_px']:.1f} px  "
                           f"IoU {n['shadow_iou']:.2f}")
    save_figure(fig, path)


def pose_sweep_from_runs(preset: str | os.PathLike, generator_run: str | os.PathLike, out_dir: str | os.PathLike,
                         cfg: SweepConfig = SweepConfig(), device="cpu") -> Report:
    """Pose sweeps of a preset's first target through a trained SAS GAN (renders with Mitsuba)."""
    from gan.train import load_generator
    from gan.translate import translate
    from sasmi.mitsuba_render import Renderer
    from sasmi.scene import load_preset

    scene = load_preset(preset).sample(cfg.seed, 0)
    generator = load_generator(generator_run, device)
    renderer = Renderer(size=generator.image_size, spp=cfg.spp)
    return pose_sweep(scene, renderer.render, lambda images: translate(generator, images, batch=cfg.batch),
                      out_dir, cfg)


def skipped_pose_sweep(reason: str) -> Report:
    return Report({"pose_sweep": {"skipped": reason}}, (Section("Pose sweeps", f"Skipped: {reason}."),))
