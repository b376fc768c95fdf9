"""Mitsuba against POV-Ray on the same Scene: do both front ends render it the same way?

Each renderer contributes a `Side`, made the same way from its own output:
- `radiance`: the noise-free gray level before speckle and noise (Mitsuba at SPP samples
  per pixel, POV-Ray with every light traced and 3 x 3 jittered sub-pixel rays);
- `blackened`: the scene with albedo-0 targets, which only block light, and `bare`: the
  scene without targets (the seafloor does not depend on them);
- `target`: pixels whose centre sees a target (Mitsuba: `Renderer.visibility`, its own
  ray casts; POV-Ray: a pass with targets white, the floor black and no lights).

Shadow, by one rule on both sides: a pixel that is not a target and gets less than
SHADOW_RATIO of the light the bare seafloor gets there (blackened / bare). Ripple facets
that face away or shade each other are dark in the bare render too, so they are not
shadow. Black rather than real targets keep pixels that a bright target face only
partly covers from swinging the ratio: a 1/10 error in covered area then moves it by
1/10, not by the 10x brighter face. Pixels that both renderers put within SHADOW_BAND of
the threshold (penumbra and part-covered pixels, where 256 spp and 10 sub-pixel rays
disagree by a few hundredths) are left out of the shadow IoU; one renderer judging a
pixel firmly is enough to count it.

Why these catch a real mismatch (64 x 64, cylinder_chip scene 0): the target moved by
0.1 m (one pixel) on one side gives target IoU 0.83; by 0.25 m, r 0.88 and shadow IoU
0.83; yawed by 30 deg, r 0.43; a cone a tenth as wide, r 0.69. Pearson r is blind to a
smooth brightness gradient: POV-Ray lights without inverse-square falloff, matched at
the chip centre, still give r 0.986, so the brightness scale is also compared over the
near and far half of the chip in range (`range_trend`).

Metrics: Pearson r of all pixels' radiance, the brightness scale (mean POV-Ray over mean
Mitsuba) and its range trend, IoU of the shadow masks and of the target masks (1 when
both are empty), and each renderer's wall time for the radiance render.
"""
from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sasmi.render import povray
from sasmi.render.geometry import build_geometry
from sasmi.images import write_gray, write_text
from sasmi.render.mitsuba import Renderer
from sasmi.scene.model import Scene

SPP = 256  # Mitsuba samples per pixel: two seeds against each other give r = 0.998
SHADOW_RATIO = 0.5  # shadow: less than half the irradiance the bare seafloor gets at that pixel
SHADOW_BAND = 0.1  # pixels that both renderers put within SHADOW_RATIO +- this are left out of the shadow IoU
MIN_PEARSON_R = 0.95
MIN_SHADOW_IOU = 0.9
MIN_TARGET_IOU = 0.9
MAX_SCALE_ERROR = 0.05  # on brightness_scale and range_trend
DIFF_GAIN = 4.0  # diff.png = 0.5 + DIFF_GAIN * (povray.png - mitsuba.png): a 1/8 gray-level error saturates
EXPOSURE_MARGIN = 0.9  # POV-Ray gray levels stay below this, so nothing clips


@dataclass(frozen=True)
class Side:
    """One renderer's view of a scene, all (H, W)."""
    radiance: np.ndarray  # float64 gray level before post-processing, not clipped
    bare: np.ndarray  # float64, the scene without its targets
    blackened: np.ndarray  # float64, the scene with black targets: they only block light
    target: np.ndarray  # bool, a target is seen through the pixel centre
    seconds: float  # wall time of the radiance render, loading the scene included

    @property
    def shadow_ratio(self) -> np.ndarray:
        """Blackened over bare radiance: the share of the bare seafloor's light a pixel still gets.

        1 where it is not judged: a target is seen there, or the bare seafloor is dark.
        """
        judged = ~self.target & (self.bare > 0)
        return np.where(judged, self.blackened / np.where(judged, self.bare, 1.0), 1.0)

    @property
    def shadow(self) -> np.ndarray:
        return self.shadow_ratio < SHADOW_RATIO


@dataclass(frozen=True)
class Metrics:
    pearson_r: float
    brightness_scale: float  # mean POV-Ray radiance / mean Mitsuba radiance
    range_trend: float  # brightness_scale over the far half of the chip / over the near half
    shadow_iou: float
    target_iou: float
    mitsuba_seconds: float
    povray_seconds: float

    @property
    def passed(self) -> bool:
        return all(self.checks().values())

    def checks(self) -> dict[str, bool]:
        return {
            "pearson_r": self.pearson_r >= MIN_PEARSON_R,
            "brightness_scale": abs(self.brightness_scale - 1) <= MAX_SCALE_ERROR,
            "range_trend": abs(self.range_trend - 1) <= MAX_SCALE_ERROR,
            "shadow_iou": self.shadow_iou >= MIN_SHADOW_IOU,
            "target_iou": self.target_iou >= MIN_TARGET_IOU,
        }


@dataclass(frozen=True)
class Crosscheck:
    scene: Scene
    mitsuba: Side
    povray: Side
    metrics: Metrics
    sdl: str  # the POV-Ray scene, as written to scene.pov


def without_targets(scene: Scene) -> Scene:
    return dataclasses.replace(scene, targets=())


def with_black_targets(scene: Scene) -> Scene:
    return dataclasses.replace(scene, targets=tuple(dataclasses.replace(t, albedo=0.0) for t in scene.targets))


def mitsuba_side(scene: Scene, renderer: Renderer) -> Side:
    """Mitsuba's renders of `scene` (as it is, with black targets, without targets) and its target mask."""
    g = build_geometry(scene, renderer.size)
    start = time.perf_counter()
    renderer.prepare(g)
    lit = renderer.radiance(scene.seed).astype(np.float64)
    seconds = time.perf_counter() - start
    visible, _ = renderer.visibility(g)
    renderer.prepare(build_geometry(with_black_targets(scene), renderer.size))
    blackened = renderer.radiance(scene.seed).astype(np.float64)
    renderer.prepare(build_geometry(without_targets(scene), renderer.size))
    bare = renderer.radiance(scene.seed).astype(np.float64)
    return Side(radiance=lit, bare=bare, blackened=blackened, target=visible >= 0, seconds=seconds)


def povray_side(scene: Scene, size: int) -> tuple[Side, str]:
    """POV-Ray's Side of `scene` and the SDL text it rendered."""
    g = build_geometry(scene, size)
    sdl = povray.geometry_sdl(g, title=f"sasmi scene, seed {scene.seed}")
    exposure = EXPOSURE_MARGIN / povray.radiance_bound(g)  # no brighter without targets or with black ones
    lit, seconds = povray.radiance(sdl, size, exposure)
    blackened, _ = povray.radiance(povray.scene_sdl(with_black_targets(scene), size), size, exposure)
    bare, _ = povray.radiance(povray.scene_sdl(without_targets(scene), size), size, exposure)
    return Side(radiance=lit, bare=bare, blackened=blackened, target=povray.target_mask(sdl, size),
                seconds=seconds), sdl


def pearson_r(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    norm = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / norm) if norm > 0 else 0.0  # a constant image correlates with nothing


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = (a | b).sum()
    return float((a & b).sum() / union) if union else 1.0


def shadow_iou(a: Side, b: Side) -> float:
    """IoU of the shadow masks over the pixels that at least one renderer judges firmly."""
    ra, rb = a.shadow_ratio, b.shadow_ratio
    judged = ~((np.abs(ra - SHADOW_RATIO) < SHADOW_BAND) & (np.abs(rb - SHADOW_RATIO) < SHADOW_BAND))
    return iou(judged & a.shadow, judged & b.shadow)


def brightness_scale(mitsuba: np.ndarray, pov: np.ndarray) -> float:
    mean = mitsuba.mean()
    return float(pov.mean() / mean) if mean > 0 else float("inf")


def compare(mitsuba: Side, pov: Side) -> Metrics:
    half = mitsuba.radiance.shape[1] // 2  # columns are ground range
    near = brightness_scale(mitsuba.radiance[:, :half], pov.radiance[:, :half])
    far = brightness_scale(mitsuba.radiance[:, half:], pov.radiance[:, half:])
    return Metrics(
        pearson_r=pearson_r(mitsuba.radiance, pov.radiance),
        brightness_scale=brightness_scale(mitsuba.radiance, pov.radiance),
        range_trend=far / near if near > 0 else float("inf"),
        shadow_iou=shadow_iou(mitsuba, pov),
        target_iou=iou(mitsuba.target, pov.target),
        mitsuba_seconds=mitsuba.seconds,
        povray_seconds=pov.seconds,
    )


def crosscheck(scene: Scene, size: int = 256) -> Crosscheck:
    """Render `scene` with both front ends at `size` x `size` and compare them."""
    renderer = Renderer(size=size, spp=SPP)  # checks the size before anything renders
    pov, sdl = povray_side(scene, size)  # first, so that a missing povray fails at once
    mitsuba = mitsuba_side(scene, renderer)
    return Crosscheck(scene=scene, mitsuba=mitsuba, povray=pov, metrics=compare(mitsuba, pov), sdl=sdl)


def side_by_side(*images: np.ndarray, gap: int = 4) -> np.ndarray:
    """Images in a row on a mid-gray background."""
    h = images[0].shape[0]
    row = [np.full((h, gap), 0.5)]
    for image in images:
        row += [image, np.full((h, gap), 0.5)]
    return np.concatenate(row, axis=1)


def write(result: Crosscheck, out: str | Path, provenance: dict) -> None:
    """mitsuba.png, povray.png (gray levels clipped to [0, 1]), diff.png, side_by_side.png,
    scene.pov and metrics.json (metrics, thresholds, `provenance`)."""
    out = Path(out)
    mitsuba, pov = np.clip(result.mitsuba.radiance, 0, 1), np.clip(result.povray.radiance, 0, 1)
    diff = np.clip(0.5 + DIFF_GAIN * (pov - mitsuba), 0, 1)  # of the PNGs: noise above white is not shown
    write_gray(out / "mitsuba.png", mitsuba)
    write_gray(out / "povray.png", pov)
    write_gray(out / "diff.png", diff)
    write_gray(out / "side_by_side.png", side_by_side(mitsuba, pov, diff))
    write_text(out / "scene.pov", result.sdl)
    m = result.metrics
    record = {
        **dataclasses.asdict(m),
        "passed": m.passed,
        "checks": m.checks(),
        "thresholds": {"pearson_r": f">= {MIN_PEARSON_R}", "brightness_scale": f"1 +- {MAX_SCALE_ERROR}",
                       "range_trend": f"1 +- {MAX_SCALE_ERROR}", "shadow_iou": f">= {MIN_SHADOW_IOU}",
                       "target_iou": f">= {MIN_TARGET_IOU}"},
        "shadow_pixels": {"mitsuba": int(result.mitsuba.shadow.sum()), "povray": int(result.povray.shadow.sum())},
        "target_pixels": {"mitsuba": int(result.mitsuba.target.sum()), "povray": int(result.povray.target.sum())},
        "mitsuba_spp": SPP,
        "emitters": result.scene.sonar.emitters,
        "diff_png": f"0.5 + {DIFF_GAIN:g} * (povray.png - mitsuba.png)",
        **provenance,
    }
    write_text(out / "metrics.json", json.dumps(record, indent=2) + "\n")


def table(m: Metrics) -> str:
    """The metrics as a small text table, with the thresholds the check applies."""
    checks = m.checks()
    rows = [
        ("Pearson r", f"{m.pearson_r:.4f}", f">= {MIN_PEARSON_R}", "pearson_r"),
        ("brightness scale", f"{m.brightness_scale:.4f}", f"1 +- {MAX_SCALE_ERROR}", "brightness_scale"),
        ("range trend", f"{m.range_trend:.4f}", f"1 +- {MAX_SCALE_ERROR}", "range_trend"),
        ("shadow IoU", f"{m.shadow_iou:.4f}", f">= {MIN_SHADOW_IOU}", "shadow_iou"),
        ("target IoU", f"{m.target_iou:.4f}", f">= {MIN_TARGET_IOU}", "target_iou"),
        ("Mitsuba time", f"{m.mitsuba_seconds:.2f} s", f"{SPP} spp", ""),
        ("POV-Ray time", f"{m.povray_seconds:.2f} s", "every light", ""),
    ]
    lines = [f"{'metric':<18}{'value':>10}  pass if"]
    for name, value, rule, key in rows:
        mark = ("ok" if checks[key] else "FAIL") if key else ""
        lines.append(f"{name:<18}{value:>10}  {rule:<14}{mark}".rstrip())
    return "\n".join(lines)
