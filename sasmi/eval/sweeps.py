"""Pose sweeps: one target moved along the chip diagonal and turned through 0–180°,
rendered, translated, and measured as in target preservation.

Only `pose_sweep_from_runs` touches Mitsuba and the generator (imported inside it), so
everything else runs without them.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.eval.config import PreservationConfig, SweepConfig
from sasmi.eval.preservation import measure_image
from sasmi.eval.report import Report, Section, sweep_grid
from sasmi.labels import TargetLabel


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


def target_labels(labels) -> tuple[TargetLabel, ...]:
    """The targets of a render's labels: a sasmi.labels.ChipLabel, or the renderer's JSON dict."""
    if hasattr(labels, "targets"):
        return tuple(labels.targets)
    return tuple(TargetLabel.from_json(t) for t in labels["targets"])


def pose_sweep(scene, render: Callable, translate: Callable[[np.ndarray], np.ndarray], out_dir: str | os.PathLike,
               cfg: SweepConfig = SweepConfig(), measure_cfg: PreservationConfig = PreservationConfig()) -> Report:
    """Render and translate both sweeps of `scene`; grids and per-pose measurements.

    render(scene) → an object with .image (H, W) in [0, 1], .mask (H, W) uint8 and
    .labels (a ChipLabel or its JSON dict); translate((N, H, W) in [0, 1]) → (N, H, W) in [0, 1].
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
        targets = [target_labels(r.labels) for r in rendered]
        images = np.stack([r.image for r in rendered])  # (steps, H, W) in [0, 1]
        translated = translate(images)
        assert translated.shape == images.shape, (translated.shape, images.shape)
        poses = []
        for s, r, labelled, out in zip(scenes, rendered, targets, translated):
            before = measure_image(r.image, r.mask, labelled, measure_cfg)
            after = measure_image(out, r.mask, labelled, measure_cfg)
            t = s.targets[0]
            poses.append({"x": t.x, "y": t.y, "yaw": t.yaw, "caption": caption(t),
                          "render": _pose_numbers(before), "translated": _pose_numbers(after),
                          "measures": (before, after)})
        sweep_grid(rendered, targets, translated, poses, out_dir / f"sweep_{name}.png")
        metrics[name] = [{k: v for k, v in p.items() if k not in ("caption", "measures")} for p in poses]
        lines += [f"![{name} sweep](sweep_{name}.png)", ""]
    return Report({"pose_sweep": metrics}, (Section("Pose sweeps", "\n".join(lines)),))


def _pose_numbers(m: dict) -> dict:
    return {"centroid_error_px": m["centroid_errors"][0], "shadow_iou": m["shadow_iou"],
            "target_contrast": m["target_contrast"]}


def pose_sweep_from_runs(preset: str | os.PathLike, generator_run: str | os.PathLike, out_dir: str | os.PathLike,
                         cfg: SweepConfig = SweepConfig(), device="cpu") -> Report:
    """Pose sweeps of a preset's first target through a trained SAS GAN (renders with Mitsuba)."""
    from sasmi.gan.generator import load_generator
    from sasmi.gan.translate import translate
    from sasmi.render import Renderer
    from sasmi.scene.preset import load_preset

    scene = load_preset(preset).sample(cfg.seed, 0)
    generator = load_generator(generator_run, device)
    renderer = Renderer(size=generator.image_size, spp=cfg.spp)
    # one tone-style code for every pose (when the generator has a style): the sweep varies the pose alone
    return pose_sweep(scene, renderer.render,
                      lambda images: translate(generator, images, batch=cfg.batch, seeds=[cfg.seed] * len(images)),
                      out_dir, cfg)


def skipped_pose_sweep(reason: str) -> Report:
    return Report({"pose_sweep": {"skipped": reason}}, (Section("Pose sweeps", f"Skipped: {reason}."),))
