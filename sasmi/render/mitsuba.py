"""Scene -> Mitsuba scene -> radiance; with the masks and label: the forward render.

Render model: Lambertian seafloor and targets lit by spot lights along the track, seen
by an orthographic camera straight down (the paper's POV-Ray set-up). The `direct`
integrator samples one emitter per sample, so cost does not grow with the number of
emitters. The radiance is scaled so that flat albedo-1 sand at the chip centre has gray
level `post.gain * sonar.intensity` (see `geometry.exposure`); `sasmi.render.post` then
applies the sonar's gain, speckle and noise.

Consecutive scenes with the same structure (pixel count, emitter count, target vertex
counts) update the loaded Mitsuba scene through `mi.traverse`, so the JIT compiles the
render kernel once per process and later images cost only the render itself. Target
meshes are padded to a common size (`padded`) so that a chip of another kind, like a
spot of another cone angle, is an update too, not a new scene. An update still rebuilds the
whole scene's BVH (Mitsuba commits every shape again at Embree's high build quality): a floor
behind an instance rebuilds alone and faster but traces slower, and padding the target count
to one structure makes every update dearer, so neither is done (benchmarks/render.py times it). A render
set, or a calibration's trial, renders its chips grouped by structure instead (sasmi.renderset.order).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from sasmi.errors import SasmiError
from sasmi.labels import ChipLabel
from sasmi.preprocess import check_size
from sasmi.masks import instance_ids
from sasmi.render.annotate import chip_label, class_mask, clutter_in_slant, labels_dict
from sasmi.render.bsdf import bsdf_dict
from sasmi.render.bsdf import register as register_bsdf
from sasmi.render.geometry import Geometry, TriangleMesh, build_geometry
from sasmi.render.llvm import aligned, import_mitsuba
from sasmi.render.post import post_maps, postprocess
from sasmi.render.slant import labels_to_slant, slant_map, to_slant
from sasmi.render.visibility import (CAMERA_HEIGHT, Occluders, camera_hits, mask_pixels, mi_mesh, shape_ids,
                                    visibility)
from sasmi.scene.model import Scene


TARGET_BUCKET = (1024, 2048)  # vertices, faces: every built-in kind fits (a sphere has 642, 1280)


def padded(mesh: TriangleMesh) -> TriangleMesh:
    """`mesh` grown to TARGET_BUCKET (or the next power of two) with copies of its first vertex and
    empty triangles, which no ray hits and which leave its bounds as they were."""
    vertices, faces = len(mesh.vertices), len(mesh.faces)
    more_vertices = max(TARGET_BUCKET[0], 1 << (vertices - 1).bit_length()) - vertices
    more_faces = max(TARGET_BUCKET[1], 1 << (faces - 1).bit_length()) - faces
    return replace(mesh, vertices=np.concatenate([mesh.vertices, np.repeat(mesh.vertices[:1], more_vertices, 0)]),
                   faces=np.concatenate([mesh.faces, np.zeros((more_faces, 3), mesh.faces.dtype)]))


@dataclass(frozen=True)
class Rendered:
    image: np.ndarray  # (H, W) float32 in [0, 1]
    mask: np.ndarray  # (H, W) uint8: 0 seafloor, 1 target, 2 acoustic shadow
    label: ChipLabel  # index 0 and no paths: the render set's writer fills those in
    instances: np.ndarray  # (H, W) uint8: 0 none, k + 1 where target k is seen
    shadows: np.ndarray  # (H, W) uint8: 0 none, k + 1 where target k casts its shadow

    @property
    def labels(self) -> dict:
        """The label as a plain dict: sonar, seafloor, post, seed, targets, size."""
        return labels_dict(self.label)


def spot_to_world(mi, position: np.ndarray, aim: np.ndarray):
    return mi.ScalarTransform4f().look_at(origin=position.tolist(), target=aim.tolist(), up=[0, 0, 1])


def load_scene(mi, dr, g: Geometry, spp: int):
    """A fresh Mitsuba scene showing `g`: floor, targets (target_k), one spot per emitter (emitter_k)."""
    # Mitsuba's camera x axis points left of the image; mirror it so range grows to the right.
    camera = (mi.ScalarTransform4f().look_at(origin=[0, 0, CAMERA_HEIGHT], target=[0, 0, 0], up=[0, -1, 0])
              @ mi.ScalarTransform4f().scale([-1, 1, 1]))
    d = {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "orthographic",
            "to_world": camera,
            "near_clip": 1.0,
            "far_clip": 2 * CAMERA_HEIGHT,
            "film": {"type": "hdrfilm", "width": g.size, "height": g.size, "pixel_format": "luminance",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    for name, mesh in (("floor", g.floor), *((f"target_{k}", t) for k, t in enumerate(g.targets))):
        if mesh.cos_power != 1:
            register_bsdf(mi, dr)
        d[name] = mi_mesh(mi, name, mesh)
        d[name].set_bsdf(mi.load_dict(bsdf_dict(mesh.albedo, mesh.cos_power)))
    # One intensity texture shared by every spot: traverse lists it once, under emitter_0.
    intensity = mi.load_dict({"type": "uniform", "value": g.emitter_intensity})
    for k, (p, aim) in enumerate(zip(g.emitter_positions, g.aims)):
        d[f"emitter_{k}"] = {"type": "spot", "to_world": spot_to_world(mi, p, aim), "cutoff_angle": g.cone_angle,
                             "beam_width": g.beam_width, "intensity": intensity}
    return mi.load_dict(d)


def checked_mitsuba(size: int, spp: int):
    """(mitsuba, drjit) for a renderer of `size` px and `spp` samples per pixel, once both are checked."""
    check_size(size, "size")
    if spp <= 0:
        raise SasmiError(f"spp: {spp} is not allowed (allowed: >= 1)")
    return import_mitsuba()


class Renderer:
    """Renders scenes at one size and sample count, reusing the compiled kernel."""

    def __init__(self, size: int = 256, spp: int = 16):
        self.mi, self.dr = checked_mitsuba(size, spp)
        self.size, self.spp = size, spp
        self._structure = None
        self._scene = None
        self._params = None
        self._occluders: Occluders | None = None
        self._target_ids: np.ndarray | None = None

    # -- scene construction -------------------------------------------------------------
    def _load(self, g: Geometry) -> None:
        self._scene = load_scene(self.mi, self.dr, g, self.spp)
        self._params = self.mi.traverse(self._scene)
        self._occluders = Occluders(self.mi, self.dr, g)
        self._target_ids = shape_ids(self.mi, self.dr, self._scene, len(g.targets))
        self._structure = g.structure

    def _update(self, g: Geometry) -> None:
        p = self._params
        p["floor.vertex_positions"] = aligned(g.floor.vertices)
        p["floor.bsdf.reflectance.value"] = g.floor.albedo
        for k, t in enumerate(g.targets):
            p[f"target_{k}.vertex_positions"] = aligned(t.vertices)
            p[f"target_{k}.faces"] = aligned(t.faces, np.uint32)  # another kind of target: other triangles
            p[f"target_{k}.bsdf.reflectance.value"] = t.albedo
        self._occluders.update(g)
        for k, (pos, aim) in enumerate(zip(g.emitter_positions, g.aims)):
            p[f"emitter_{k}.to_world"] = spot_to_world(self.mi, pos, aim)
            p[f"emitter_{k}.cutoff_angle"] = g.cone_angle
            p[f"emitter_{k}.beam_width"] = g.beam_width
        p["emitter_0.intensity.value"] = g.emitter_intensity
        p.update()

    def prepare(self, g: Geometry) -> None:
        """Load or update the Mitsuba scene so that it shows `g`."""
        g = replace(g, targets=tuple(padded(t) for t in g.targets))
        if g.structure != self._structure:
            self._load(g)
        else:
            self._update(g)

    @property
    def mitsuba_scene(self):
        return self._scene

    @property
    def params(self):
        return self._params

    # -- rendering ----------------------------------------------------------------------
    def launch(self, seed: int):
        """Start rendering the prepared scene; Dr.Jit runs it in its own threads until `collect`."""
        return self.mi.render(self._scene, spp=self.spp, seed=seed % (2**31))

    def collect(self, launched) -> np.ndarray:
        """(H, W) float32 radiance of a launched render, exposure folded in (not clipped)."""
        return np.asarray(launched, dtype=np.float32).reshape(self.size, self.size)

    def radiance(self, seed: int) -> np.ndarray:
        return self.collect(self.launch(seed))

    def camera_hits(self, pixels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(H*W,) shape registry ids and surface heights (chip units) of the prepared scene at the pixel
        centres (at `pixels` only, when given: see `visibility.camera_hits`)."""
        return camera_hits(self.mi, self.dr, self._scene, self.size, pixels)

    def visibility(self, g: Geometry, hits: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) each: visible target index and shadowing target index (-1 none) of the prepared `g`."""
        ids, heights = hits if hits is not None else self.camera_hits(mask_pixels(g))
        return visibility(ids, heights, self._target_ids, self._occluders, g)

    def render(self, scene: Scene) -> Rendered:
        g = build_geometry(scene, self.size)
        self.prepare(g)
        launched = self.launch(scene.seed)
        maps = post_maps(scene, g)  # numpy work while the render runs
        pixels = None if scene.sonar.slant_range else mask_pixels(g)  # slant range needs every height
        radiance = self.collect(launched)
        hits = self.camera_hits(pixels)
        visible, owner = self.visibility(g, hits)
        if scene.sonar.slant_range:
            return self._render_slant(scene, g, radiance, maps, visible, owner, hits[1].reshape(self.size, self.size))
        return Rendered(image=postprocess(radiance, maps), mask=class_mask(visible, owner),
                        label=chip_label(scene, visible, owner, self.size, floor_rocks=g.rocks),
                        instances=instance_ids(visible), shadows=instance_ids(owner))

    def _render_slant(self, scene: Scene, g: Geometry, radiance: np.ndarray, maps, visible, owner,
                      heights: np.ndarray) -> Rendered:
        """The chip with its x axis in slant range (sasmi.render.slant): gain before the move, speckle after."""
        gain, speckle, offset = maps
        m = slant_map(g, heights)
        image = postprocess(to_slant(radiance * gain, m), (np.ones_like(gain), speckle, offset))
        visible, owner = labels_to_slant(visible, owner, m)
        label = chip_label(scene, visible, owner, self.size, floor_rocks=g.rocks)
        unit = 2.0 / scene.sonar.chip_size
        targets = tuple(replace(t, pixel_centre=(float(m.column(t.params["x"] * unit, 0.0)), t.pixel_centre[1]))
                        for t in label.targets)
        label = replace(label, targets=targets, clutter=clutter_in_slant(label.clutter, m.column, self.size, unit))
        return Rendered(image=image, mask=class_mask(visible, owner), label=label,
                        instances=instance_ids(visible), shadows=instance_ids(owner))


@lru_cache(maxsize=4)
def renderer_for(size: int, spp: int) -> Renderer:
    """One Renderer per (size, spp), made on first use.

    An explicit, bounded cache rather than a module-level dict: a Renderer holds a loaded
    scene and its compiled kernel, which is what makes the second call cheap, but also its
    memory, so only the few most recent (size, spp) pairs are kept; tests and long-running
    callers can drop them with `renderer_for.cache_clear()`.
    """
    return Renderer(size=size, spp=spp)


def render(scene: Scene, size: int = 256, spp: int = 16) -> Rendered:
    """One-call API: image, mask and labels of `scene` (renderers are reused per size/spp)."""
    return renderer_for(size, spp).render(scene)
