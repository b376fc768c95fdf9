"""The one module that owns Mitsuba and Dr.Jit: Geometry -> image, mask and labels.

Render model: Lambertian seafloor and targets lit by spot lights along the track, seen
by an orthographic camera straight down (the paper's POV-Ray set-up). The `direct`
integrator samples one emitter per sample, so cost does not grow with the number of
emitters. The radiance is scaled so that flat albedo-1 sand at the chip centre has gray
level `post.gain * sonar.intensity` (see `geometry.exposure`); then an optional
time-varying gain evens out the flat-floor brightness over range (as a sonar's TVG does),
then optional speckle and noise; the result is clipped to [0, 1].

Consecutive scenes with the same structure (pixel count, emitter count, target vertex
counts) update the loaded Mitsuba scene through `mi.traverse`, so the JIT compiles the
render kernel once per process and later images cost only the render itself.
"""
from __future__ import annotations

import dataclasses
import glob
import os
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sasmi.errors import SasmiError
from sasmi.geometry import Geometry, TriangleMesh, build_geometry, tvg_gain
from sasmi.scene import Scene, scene_to_dict
from sasmi.seafloor import height_array, height_at

if TYPE_CHECKING:
    import torch

VARIANT = "llvm_ad_mono"
MASK_SEAFLOOR, MASK_TARGET, MASK_SHADOW = 0, 1, 2
LLVM_HINT = ("Mitsuba's CPU backend needs LLVM 19: install it with `apt-get install libllvm19` "
             "(or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version 16 or newer)")
CAMERA_HEIGHT = 50.0  # chip units above the floor; far above any target
SHADOW_FRACTION = 0.5  # a floor point is in acoustic shadow when a target hides it from half the array
SHADOW_PROBES = 8  # emitters, evenly spread over the array, that the shadow mask is tested against


def _llvm_version(path: str) -> int | None:
    m = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def _find_llvm() -> str | None:
    """Newest libLLVM >= 16 on the system; Debian 12's default 14/15 crash Dr.Jit 1.5."""
    found = []
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/llvm-*/lib/libLLVM*.so*"):
        version = _llvm_version(path)
        if version is not None and version >= 16:
            found.append((version, path))
    return max(found)[1] if found else None


def _import_mitsuba():
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        path = _find_llvm()
        if path is None:
            raise SasmiError(LLVM_HINT)
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    version = _llvm_version(os.environ["DRJIT_LIBLLVM_PATH"])
    if version is not None and version < 16:  # would abort the process later ("Cannot select ... fminimum")
        raise SasmiError(f"DRJIT_LIBLLVM_PATH points at LLVM {version}; {LLVM_HINT}")
    import drjit as dr
    import mitsuba as mi

    try:
        mi.set_variant(VARIANT)
    except (ImportError, RuntimeError) as e:
        raise SasmiError(f"{LLVM_HINT} ({e})") from None
    return mi, dr


def versions() -> dict:
    mi, dr = _import_mitsuba()
    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": VARIANT,
            "llvm": os.environ.get("DRJIT_LIBLLVM_PATH", "")}


def aligned(a: np.ndarray, dtype=np.float32) -> np.ndarray:
    """A flat copy of `a` on a 64-byte boundary, for handing to Dr.Jit.

    Dr.Jit maps numpy memory without copying and compiles one kernel variant for aligned
    and one for unaligned inputs, so arrays of random alignment would trigger random
    recompiles (seconds each); aligned copies keep every scene on one cached kernel.
    """
    a = np.asarray(a, dtype=dtype).ravel()
    items = 64 // a.itemsize
    buffer = np.empty(a.size + items, dtype=dtype)
    start = (-buffer.ctypes.data % 64) // a.itemsize
    out = buffer[start:start + a.size]
    out[:] = a
    return out


@dataclass(frozen=True)
class Rendered:
    image: np.ndarray  # (H, W) float32 in [0, 1]
    mask: np.ndarray  # (H, W) uint8: 0 seafloor, 1 target, 2 acoustic shadow
    labels: dict


def _mi_mesh(mi, name: str, mesh: TriangleMesh):
    m = mi.Mesh(name, vertex_count=len(mesh.vertices), face_count=len(mesh.faces), has_vertex_normals=False)
    params = mi.traverse(m)
    params["vertex_positions"] = aligned(mesh.vertices)
    params["faces"] = aligned(mesh.faces, np.uint32)
    params.update()
    return m


class Renderer:
    """Renders scenes at one size and sample count, reusing the compiled kernel."""

    def __init__(self, size: int = 256, spp: int = 16):
        if size <= 0 or size % 16:
            raise SasmiError(f"size: {size} is not allowed (allowed: a positive multiple of 16)")
        if spp <= 0:
            raise SasmiError(f"spp: {spp} is not allowed (allowed: >= 1)")
        self.size, self.spp = size, spp
        self.mi, self.dr = _import_mitsuba()
        self._structure = None
        self._scene = None
        self._params = None
        self._target_ids: np.ndarray | None = None

    # -- scene construction -------------------------------------------------------------
    def _spot_to_world(self, position: np.ndarray, aim: np.ndarray):
        return self.mi.ScalarTransform4f().look_at(origin=position.tolist(), target=aim.tolist(), up=[0, 0, 1])

    def _load(self, g: Geometry) -> None:
        mi = self.mi
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
                "sampler": {"type": "independent", "sample_count": self.spp},
            },
            "floor": _mi_mesh(mi, "floor", g.floor),
        }
        d["floor"].set_bsdf(mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": g.floor.albedo}}))
        for k, t in enumerate(g.targets):
            m = _mi_mesh(mi, f"target_{k}", t)
            m.set_bsdf(mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": t.albedo}}))
            d[f"target_{k}"] = m
        # One intensity texture shared by every spot: traverse lists it once, under emitter_0.
        intensity = mi.load_dict({"type": "uniform", "value": g.emitter_intensity})
        for k, p in enumerate(g.emitter_positions):
            d[f"emitter_{k}"] = {
                "type": "spot",
                "to_world": self._spot_to_world(p, g.aim),
                "cutoff_angle": g.cone_angle,
                "beam_width": g.beam_width,
                "intensity": intensity,
            }
        self._scene = mi.load_dict(d)
        self._params = mi.traverse(self._scene)
        # Shadow rays are traced against the targets alone, so a ripple between a floor
        # point and a target does not punch a hole in that target's acoustic shadow.
        self._occluders = mi.load_dict({"type": "scene", **{f"target_{k}": _mi_mesh(mi, f"target_{k}", t)
                                                              for k, t in enumerate(g.targets)}})
        self._occluder_params = mi.traverse(self._occluders)
        self._target_ids = self._shape_ids(self._scene, len(g.targets))
        self._occluder_ids = self._shape_ids(self._occluders, len(g.targets))
        self._structure = g.structure

    def _shape_ids(self, scene, count: int) -> np.ndarray:
        by_name = {s.id(): s for s in scene.shapes()}
        return np.array([self.dr.reinterpret_array(self.mi.UInt32, self.mi.ShapePtr(by_name[f"target_{k}"]))[0]
                         for k in range(count)], dtype=np.int64)

    def _update(self, g: Geometry) -> None:
        p = self._params
        p["floor.vertex_positions"] = aligned(g.floor.vertices)
        p["floor.bsdf.reflectance.value"] = g.floor.albedo
        for k, t in enumerate(g.targets):
            p[f"target_{k}.vertex_positions"] = aligned(t.vertices)
            p[f"target_{k}.bsdf.reflectance.value"] = t.albedo
            self._occluder_params[f"target_{k}.vertex_positions"] = aligned(t.vertices)
        if g.targets:
            self._occluder_params.update()
        for k, pos in enumerate(g.emitter_positions):
            p[f"emitter_{k}.to_world"] = self._spot_to_world(pos, g.aim)
        p["emitter_0.intensity.value"] = g.emitter_intensity
        p.update()

    def prepare(self, g: Geometry) -> None:
        """Load or update the Mitsuba scene so that it shows `g`."""
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

    def visibility(self, g: Geometry) -> tuple[np.ndarray, np.ndarray]:
        """Per pixel: index of the visible target (-1 none) and of the target shadowing it (-1 none).

        Camera rays through pixel centres find the visible surface; from each floor hit a
        ray towards every emitter asks which target, if any, is hit first. A floor point
        hidden by a target from at least SHADOW_FRACTION of SHADOW_PROBES emitters spread over
        the array is acoustic shadow.
        """
        mi, dr = self.mi, self.dr
        n = self.size
        centres = (np.arange(n) + 0.5) / n * 2 - 1
        xs, ys = np.meshgrid(centres, centres)
        origin = mi.Point3f(aligned(xs), aligned(ys), aligned(np.full(n * n, CAMERA_HEIGHT)))
        si = self._scene.ray_intersect(mi.Ray3f(origin, mi.Vector3f(0, 0, -1)))
        hit_ids = np.asarray(dr.reinterpret_array(mi.UInt32, si.shape), dtype=np.int64)
        visible = self._index_of(hit_ids, self._target_ids)

        lifted = np.asarray(si.p + si.n * 1e-4, dtype=np.float32).reshape(3, -1).T  # (P, 3)
        emitters = shadow_emitters(g.emitter_positions).astype(np.float32)  # (K, 3)
        owner = np.full(n * n, -1, dtype=np.int64)
        candidates = np.nonzero(shadow_candidates(g, lifted) & (visible < 0))[0]
        if candidates.size:
            # One launch for all probes: positions travel as array data, not as kernel
            # literals, so the kernel compiles once and serves every scene.
            points = lifted[candidates]
            origins = np.tile(points, (len(emitters), 1))  # (K * C, 3), probe-major
            to_light = np.repeat(emitters, len(points), axis=0) - origins
            dist = np.linalg.norm(to_light, axis=1)
            directions = to_light / dist[:, None]
            rays = mi.Ray3f(mi.Point3f(*(aligned(origins[:, i]) for i in range(3))),
                            mi.Vector3f(*(aligned(directions[:, i]) for i in range(3))))
            hits = self._occluders.ray_intersect(mi.Ray3f(rays, mi.Float(aligned(dist * (1 - 1e-4)))))
            blocker = self._index_of(np.asarray(dr.reinterpret_array(mi.UInt32, hits.shape), dtype=np.int64),
                                     self._occluder_ids)
            counts = np.zeros((len(g.targets) + 1, len(points)), dtype=np.int32)  # row 0: nothing in the way
            for per_probe in blocker.reshape(len(emitters), len(points)):
                counts[per_probe + 1, np.arange(len(points))] += 1  # one blocker per point: no repeats
            blocked = counts[1:]
            owner[candidates] = np.where(blocked.max(axis=0) >= SHADOW_FRACTION * len(emitters),
                                         blocked.argmax(axis=0), -1)
        owner = np.where(visible >= 0, -1, owner)
        return visible.reshape(n, n), owner.reshape(n, n)

    @staticmethod
    def _index_of(shape_ids: np.ndarray, target_ids: np.ndarray) -> np.ndarray:
        """Map Mitsuba shape registry ids to target indices (-1 for floor or miss)."""
        out = np.full(shape_ids.shape, -1, dtype=np.int64)
        for k, sid in enumerate(target_ids):
            out[shape_ids == sid] = k
        return out

    def render(self, scene: Scene) -> Rendered:
        g = build_geometry(scene, self.size)
        self.prepare(g)
        launched = self.launch(scene.seed)
        maps = post_maps(scene, g)  # numpy work while the render runs
        image = postprocess(self.collect(launched), maps)
        visible, owner = self.visibility(g)
        mask = np.full((self.size, self.size), MASK_SEAFLOOR, dtype=np.uint8)
        mask[owner >= 0] = MASK_SHADOW
        mask[visible >= 0] = MASK_TARGET
        return Rendered(image=image, mask=mask, labels=labels_for(scene, visible, owner, self.size))


def shadow_emitters(positions: np.ndarray) -> np.ndarray:
    """SHADOW_PROBES emitters spread evenly over the array (all of them if there are fewer)."""
    if len(positions) <= SHADOW_PROBES:
        return positions
    return positions[np.round(np.linspace(0, len(positions) - 1, SHADOW_PROBES)).astype(int)]


def shadow_candidates(g: Geometry, points: np.ndarray) -> np.ndarray:
    """(P,) bool: floor points whose rays towards the array could pass over a target's footprint.

    A ray from floor point p to an emitter at (x_track, y_e) crosses x at the fraction
    f = (p_x - x) / (p_x - x_track) of its way; its y there is p_y + (y_e - p_y) f. The
    extremes over the footprint's x-range and the array's y-range bound where it can be.
    Only candidates are traced, which keeps the shadow mask cheap on a mostly empty chip.
    """
    px, py = points[:, 0].astype(np.float64), points[:, 1].astype(np.float64)
    x_track = g.emitter_positions[0, 0]
    ye0, ye1 = g.emitter_positions[:, 1].min(), g.emitter_positions[:, 1].max()
    out = np.zeros(len(points), dtype=bool)
    for t in g.targets:
        (x0, y0), (x1, y1) = t.vertices[:, :2].min(0), t.vertices[:, :2].max(0)
        beyond = px > x0
        span = np.maximum(px - x_track, 1e-9)
        f_near, f_far = np.clip((px - x1) / span, 0, 1), np.clip((px - x0) / span, 0, 1)
        corners = [py + (ye - py) * f for ye in (ye0, ye1) for f in (f_near, f_far)]
        out |= beyond & (np.minimum.reduce(corners) <= y1) & (np.maximum.reduce(corners) >= y0)
    return out


def post_fields(scene: Scene, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) speckle and noise fields of `scene`, seeded by it (the differentiable render reuses them)."""
    post = scene.post
    rng = np.random.default_rng([scene.seed, 11])
    speckle = np.ones((size, size))
    noise = np.zeros((size, size))
    if post.speckle_looks > 0:
        speckle = rng.gamma(post.speckle_looks, 1.0 / post.speckle_looks, size=(size, size))
    if post.noise_std > 0:
        noise = rng.normal(0.0, post.noise_std, size=(size, size))
    return speckle, noise


def post_maps(scene: Scene, g: Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(H, W) time-varying gain (1 when off), speckle (gamma, mean 1) and additive noise of `scene`."""
    gain = tvg_gain(g.emitter_positions, g.size) if scene.post.tvg else np.ones((g.size, g.size))
    return (gain, *post_fields(scene, g.size))


def postprocess(radiance: np.ndarray, maps: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Radiance × gain × speckle + noise, clipped to [0, 1]."""
    gain, speckle, noise = maps
    return np.clip(radiance.astype(np.float64) * gain * speckle + noise, 0.0, 1.0).astype(np.float32)


def _bbox(pixels: np.ndarray) -> list[int] | None:
    rows, cols = np.nonzero(pixels)
    if len(rows) == 0:
        return None
    return [int(cols.min()), int(rows.min()), int(cols.max()) + 1, int(rows.max()) + 1]


def labels_for(scene: Scene, visible: np.ndarray, owner: np.ndarray, size: int) -> dict:
    """Scene parameters plus, per target, its pixel centre and boxes (col0, row0, col1, row1; end exclusive)."""
    half = scene.sonar.chip_size / 2
    params = scene_to_dict(scene)
    targets = []
    for k, t in enumerate(params.pop("targets")):
        targets.append({
            **t,
            "pixel_centre": [(t["x"] + half) / scene.sonar.chip_size * size - 0.5,
                             (t["y"] + half) / scene.sonar.chip_size * size - 0.5],
            "bbox": _bbox(visible == k),
            "shadow_bbox": _bbox(owner == k),
            "visible_pixels": int((visible == k).sum()),
            "shadow_pixels": int((owner == k).sum()),
        })
    return {**params, "targets": targets, "size": size}


_default_renderers: dict[tuple[int, int], Renderer] = {}


def render(scene: Scene, size: int = 256, spp: int = 16) -> Rendered:
    """One-call API: image, mask and labels of `scene` (renderers are cached per size/spp)."""
    key = (size, spp)
    if key not in _default_renderers:
        _default_renderers[key] = Renderer(size=size, spp=spp)
    return _default_renderers[key].render(scene)


# ---------------------------------------------------------------------------------------
# Differentiable render (`sasmi fit-scene`): scene parameters θ → image, as a torch function
# ---------------------------------------------------------------------------------------

PARAMETERS = ("seafloor.roughness", "seafloor.albedo", "sonar.intensity", "sonar.elevation")


def scene_parameters(scene: Scene) -> np.ndarray:
    """(4,) θ of `scene` in PARAMETERS order: roughness 1 (its own relief), albedo, intensity, altitude (m)."""
    return np.array([1.0, scene.seafloor.albedo, scene.sonar.intensity, scene.sonar.altitude])


@dataclass(frozen=True)
class BoundScene:
    """A scene split into the part θ moves and the part that stays, with its own Mitsuba scene.

    Arrays are Dr.Jit Floats, xyz flattened, chip units. Each bound scene owns its Mitsuba
    scene because a render's AD graph does not survive another render of the same Mitsuba
    scene: with two scenes rendered in turn on one, only the second one's gradient reached
    θ (measured). So K scenes in one loss need K bound scenes, and one bound scene holds one
    differentiable image at a time.
    """
    scene: Scene
    geometry: Geometry  # at θ = scene_parameters(scene)
    mitsuba_scene: object  # mi.Scene
    params: object  # mi.SceneParameters of mitsuba_scene
    floor_fixed: object  # mi.Float (3V,): the vertex grid and the rocks
    floor_relief: object  # mi.Float (3V,): rough + ripple heights at roughness 1 in z, 0 in x and y
    floor_up: object  # mi.Float (3V,): 1 in z, 0 in x and y
    targets_fixed: tuple  # mi.Float (3V_k,) each: the target standing on the relief-free floor
    targets_up: tuple  # mi.Float (3V_k,) each: 1 in z
    targets_lift: tuple[float, ...]  # relief under each target's anchor at roughness 1 (targets ride on it)
    speckle: object  # mi.Float (H·W,): multiplicative field, mean 1; all 1 when off
    noise: object  # mi.Float (H·W,): additive field in gray levels; all 0 when off


class DifferentiableRenderer(Renderer):
    """θ = (roughness, albedo, intensity, altitude) → chip image, differentiable through Dr.Jit's AD.

    The image is the forward render's: the same `direct` integrator (one emitter sample, no
    BSDF sample), exposure, time-varying gain and, for a BoundScene made with speckle, the
    same speckle and noise draws as fixed fields; then clipped to [0, 1]. For every
    parameter the AD graph of one `direct` render is recorded and differentiated (the
    primal and its gradient share one sample stream, so a gradient is that of the very
    image it came with, which central differences at the same seed check). Visibility is
    not differentiated: shadow edges that move with θ are missed (docs/differentiable.md
    lists the measured gradient / finite-difference ratios).

    - roughness r scales the relief: floor z = fixed + r·relief; targets ride along.
    - albedo is the floor's diffuse reflectance; intensity is `sonar.intensity`.
    - altitude (m, = sonar.max_range / 10) moves the whole array. Mitsuba treats a spot's
      `to_world` as non-differentiable, so the emitters stay where they are loaded and the
      floor and targets are lowered by the altitude change instead: the camera is
      orthographic and straight down, so the image is the same. The spots' aim follows
      (without gradient; the chip lies well inside the beam) and the exposure and TVG
      are recomputed from the altitude inside the graph, as `build_geometry` would.
    """

    def __init__(self, size: int = 256, spp: int = 16):
        super().__init__(size, spp)
        centres = (np.arange(size) + 0.5) / size * 2 - 1
        x, y = np.meshgrid(centres, centres)
        self._pixel_x, self._pixel_y = self._upload(x), self._upload(y)  # (H·W,) pixel centres, row-major

    def _upload(self, a: np.ndarray):
        return self.mi.Float(aligned(a))

    def _opaque(self, value: float):
        return self.dr.opaque(self.mi.Float, value)

    def bind(self, scene: Scene, speckle: bool = True) -> BoundScene:
        """Split `scene` for `image`; `speckle` keeps the scene's speckle and noise draws as fixed fields.

        The relief is the heightfield without its rocks: `height_array` draws the rough
        surface, then the ripple phase, then the rocks from one generator, so dropping the
        rocks leaves the first two draws and heights = relief + rocks exactly. Scaling
        `rms_height` and `ripple_amplitude` by r scales the relief by r (the rough part is
        normalised to its rms), which is how a fitted roughness goes back into a preset.
        """
        s = scene.sonar
        unit = 2.0 / s.chip_size  # chip units per metre
        g = build_geometry(scene, self.size)
        relief = height_array(dataclasses.replace(scene.seafloor, rocks=0), s.chip_size, self.size, scene.seed)
        floor_relief = np.zeros_like(g.floor.vertices)
        floor_relief[:, 2] = relief.ravel() * unit
        lifts = tuple(height_at(relief, s.chip_size, t.x, t.y) * unit for t in scene.targets)
        fields = post_fields(scene, self.size) if speckle else (np.ones((self.size, self.size)),
                                                                np.zeros((self.size, self.size)))
        self._load(g)
        mitsuba_scene, params = self._scene, self._params
        self._structure = None  # that scene now belongs to the bound scene: `render` loads its own
        return BoundScene(
            scene=scene, geometry=g, mitsuba_scene=mitsuba_scene, params=params,
            floor_fixed=self._upload(g.floor.vertices - floor_relief),
            floor_relief=self._upload(floor_relief),
            floor_up=self._upload(np.tile([0.0, 0.0, 1.0], len(g.floor.vertices))),
            targets_fixed=tuple(self._upload(m.vertices - [0.0, 0.0, lift]) for m, lift in zip(g.targets, lifts)),
            targets_up=tuple(self._upload(np.tile([0.0, 0.0, 1.0], len(m.vertices))) for m in g.targets),
            targets_lift=lifts, speckle=self._upload(fields[0]), noise=self._upload(fields[1]))

    def image(self, bound: BoundScene, theta: "torch.Tensor", seed: int) -> "torch.Tensor":
        """(H, W) float32 in [0, 1] from θ (4,) in PARAMETERS order; gradients flow back to θ in torch."""
        assert theta.shape == (len(PARAMETERS),), theta.shape
        dr = self.dr

        @dr.wrap(source="torch", target="drjit")
        def render(theta_dr):
            return self._image(bound, theta_dr.array, seed)

        return render(theta.float())

    def gradient_image(self, bound: BoundScene, theta: np.ndarray, name: str, seed: int
                       ) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) image and its forward-mode derivative d image / d θ[name], both float32."""
        dr = self.dr
        if name not in PARAMETERS:
            raise SasmiError(f"{name}: unknown parameter (allowed: {', '.join(PARAMETERS)})")
        theta_dr = self._upload(theta)
        dr.enable_grad(theta_dr)
        image = self._image(bound, theta_dr, seed)
        dr.set_grad(theta_dr, self._upload(np.array(PARAMETERS) == name))
        dr.forward_to(image)
        return np.array(dr.detach(image)), np.array(dr.grad(image))

    def _image(self, b: BoundScene, theta, seed: int):
        """Dr.Jit side: θ Float (4,), possibly AD-attached → TensorXf (H, W) in [0, 1]."""
        mi, dr = self.mi, self.dr
        g = b.geometry
        # θ and the scene's constants enter as opaque variables: one compiled kernel serves every
        # value and every scene, and Dr.Jit 1.5's literal folding never sees them (array * literal
        # 0.0 resized the literal operand in place in our tests).
        dr.make_opaque(theta)
        roughness, albedo, intensity, altitude = (dr.gather(mi.Float, theta, i) for i in range(len(PARAMETERS)))
        height = altitude * self._opaque(2.0 / b.scene.sonar.chip_size)  # chip units
        drop = height - self._opaque(g.emitter_positions[0, 2])  # the scene moves down instead of the array up

        p = b.params
        p["floor.vertex_positions"] = b.floor_fixed + roughness * b.floor_relief - drop * b.floor_up
        p["floor.bsdf.reflectance.value"] = albedo
        for k, (fixed, up, lift, mesh) in enumerate(zip(b.targets_fixed, b.targets_up, b.targets_lift, g.targets)):
            p[f"target_{k}.vertex_positions"] = fixed + (roughness * lift - drop) * up
            p[f"target_{k}.bsdf.reflectance.value"] = mesh.albedo
        aim = np.array([0.0, 0.0, -dr.detach(drop)[0]])
        for k, position in enumerate(g.emitter_positions):
            p[f"emitter_{k}.to_world"] = self._spot_to_world(position, aim)
        centre = self._irradiance(g.emitter_positions, height, 0.0, 0.0)
        p["emitter_0.intensity.value"] = intensity * self._opaque(b.scene.post.gain * np.pi) / centre  # exposure
        p.update()

        scene = b.mitsuba_scene
        radiance = scene.integrator().render(scene, scene.sensors()[0], seed=seed % 2**31, spp=self.spp,
                                             develop=True, evaluate=False).array  # (H·W,) row-major
        if b.scene.post.tvg:
            radiance = radiance * (centre / self._irradiance(g.emitter_positions, height, self._pixel_x,
                                                             self._pixel_y))  # geometry.tvg_gain
        image = dr.clip(radiance * b.speckle + b.noise, 0.0, 1.0)
        return mi.TensorXf(image, shape=(self.size, self.size))

    def _irradiance(self, positions: np.ndarray, height, x, y):
        """Σ over the emitters of cos θ / d² on a flat floor at (x, y), the array at `height` (chip units)."""
        dr = self.dr
        total = 0.0
        for px, py in positions[:, :2].tolist():
            d2 = dr.square(self._opaque(px) - x) + dr.square(self._opaque(py) - y) + dr.square(height)
            total = total + height / (dr.sqrt(d2) * d2)
        return total
