"""Scene -> renderer-neutral geometry: triangle meshes, emitters and the exposure.

Both renderers (Mitsuba and POV-Ray) consume this, so they see the same triangles.
Everything is expressed in *chip units*: the chip spans [-1, 1] in x (range) and y
(along-track), centred at the origin, z up; one chip unit is chip_size / 2 metres.
Working in chip units keeps the camera fixed for every scene, so a preset whose chip
size varies still reuses one compiled kernel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from sasmi.errors import SasmiError
from sasmi.render.seafloor import Surface, surface
from sasmi.scene.model import Scene, Target

CYLINDER_SECTIONS = 32  # fixed so every cylinder has the same vertex count (kernel reuse)
SPHERE_SUBDIVISIONS = 3
BOULDER_LUMPS = ((6, 0.6), (24, 0.3))  # (bumps, angular width in rad) per scale: a few big lobes, many small knobs
TORUS_SECTIONS = (32, 12)  # around the ring, around the tube: 384 vertices, fixed as for cylinders


# backscatter -> power of cos(incidence) in the radiance; rough: 0.5, as an even 0 lies further from real rock
COS_POWER = {"lambert": 1, "lambert2": 2, "rough": 0.5}


@dataclass(frozen=True)
class TriangleMesh:
    vertices: np.ndarray  # (V, 3) float32, chip units
    faces: np.ndarray  # (F, 3) uint32, counter-clockwise seen from outside
    albedo: float
    cos_power: float = 1  # radiance = albedo / pi * irradiance * cos(incidence)^(cos_power - 1)


@dataclass(frozen=True)
class Geometry:
    size: int  # image width = height in pixels
    metres_per_unit: float  # chip_size / 2
    floor: TriangleMesh
    targets: tuple[TriangleMesh, ...]
    emitter_positions: np.ndarray  # (N, 3) chip units
    aims: np.ndarray  # (N, 3) chip units: where each spot points (the chip centre, or broadside with an aperture)
    cone_angle: float  # deg, cutoff half-angle
    beam_width: float  # deg, where the falloff starts
    emitter_intensity: float  # radiant intensity per emitter, exposure folded in
    broadside: bool = False  # sonar.aperture_angle > 0: the beams' falloff shapes the lighting of the chip
    rocks: tuple[tuple[float, float, float], ...] = ()  # (x, y, radius) in m: the floor's rocks, for the labels

    @property
    def beam(self) -> tuple | None:
        """(aims, cutoff, beam_width) when the beams' profiles shape the chip's lighting, else None."""
        return (self.aims, self.cone_angle, self.beam_width) if self.broadside else None

    @property
    def structure(self) -> tuple:
        """What must stay equal for a compiled renderer to be updated in place."""
        return (self.size, len(self.floor.vertices), self.floor.cos_power, len(self.emitter_positions),
                tuple((len(t.vertices), len(t.faces), t.cos_power) for t in self.targets))


def scene_structure(scene: Scene) -> tuple:
    """What `Geometry.structure` depends on, read from the scene without building it: chips with equal
    structures render as in-place updates of one loaded Mitsuba scene (built-in shapes are padded alike)."""
    targets = tuple((t.mesh if t.shape == "mesh" else "", t.backscatter) for t in scene.targets)
    return scene.sonar.emitters, scene.seafloor.backscatter, targets


def grid_faces(n: int) -> np.ndarray:
    """Two up-facing triangles per cell of an (n+1) x (n+1) vertex grid, row-major."""
    r, c = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v00 = (r * (n + 1) + c).ravel()
    v01, v10 = v00 + 1, v00 + (n + 1)
    v11 = v10 + 1
    return np.concatenate([np.stack([v00, v01, v11], 1), np.stack([v00, v11, v10], 1)]).astype(np.uint32)


def floor_mesh(heights_m: np.ndarray, chip_size: float, albedo: float, cos_power: int = 1) -> TriangleMesh:
    n = heights_m.shape[0] - 1
    scale = 2.0 / chip_size
    coords = np.linspace(-1.0, 1.0, n + 1)
    x, y = np.meshgrid(coords, coords)
    vertices = np.stack([x, y, heights_m * scale], -1).reshape(-1, 3).astype(np.float32)
    return TriangleMesh(vertices, _cached_grid_faces(n), albedo, cos_power)


@lru_cache(maxsize=4)
def _cached_grid_faces(n: int) -> np.ndarray:
    faces = grid_faces(n)
    faces.setflags(write=False)
    return faces


@lru_cache(maxsize=32)
def _load_mesh_file(path: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh")
    except FileNotFoundError:
        raise SasmiError(f"{path}: mesh file not found") from None
    except Exception as e:  # trimesh raises many types for unreadable files
        raise SasmiError(f"{path}: cannot read mesh ({e})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SasmiError(f"{path}: no triangles found")
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.uint32)


@lru_cache(maxsize=None)
def _primitive(shape: str) -> tuple[np.ndarray, np.ndarray]:
    """A unit cylinder (radius 1, height 1, axis z), sphere (radius 1) or cube (side 1), centred at the origin:
    trimesh builds one in about a millisecond, a copy scaled to each target costs microseconds."""
    import trimesh

    if shape == "cylinder":
        m = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=CYLINDER_SECTIONS)
    elif shape == "sphere":
        m = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS, radius=1.0)
    else:
        m = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    v, f = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.uint32)
    v.flags.writeable = f.flags.writeable = False  # shared by every call
    return v, f


def _unit_shape(t: Target, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Target mesh in metres, axis along +x for lying shapes (cylinder, box and boulder length), lowest point at z = 0."""
    import trimesh

    if t.shape == "cylinder":
        v, f = _primitive("cylinder")
        v = (v * [t.radius, t.radius, t.length])[:, [2, 1, 0]] * [1, 1, -1]  # a quarter turn about y: z -> x
    elif t.shape == "sphere":
        v, f = _primitive("sphere")
        v = v * t.radius
    elif t.shape == "cone":
        v, f = _primitive("cylinder")
        top = v[:, 2] > 0
        v = v * [t.radius, t.radius, t.length]
        v[top, :2] *= t.radius_top / t.radius  # frustum: shrink the top ring
    elif t.shape == "box":
        v, f = _primitive("box")
        v = v * [t.length, t.width, t.height]
    elif t.shape == "boulder":
        v, f = _boulder(t)
    elif t.shape == "torus":  # a tyre lying flat: the ring in the seabed's plane
        m = trimesh.creation.torus(major_radius=t.radius, minor_radius=t.tube_radius,
                                   major_sections=TORUS_SECTIONS[0], minor_sections=TORUS_SECTIONS[1])
        v, f = m.vertices, m.faces
    else:
        try:
            v, f = _load_mesh_file(t.mesh)
        except SasmiError as e:
            raise SasmiError(f"{where}.mesh: {e}") from None
        v = v * t.scale
    v = np.asarray(v, dtype=np.float64)
    v = v - [0.0, 0.0, v[:, 2].min()]
    return v, np.asarray(f, dtype=np.uint32)


def _boulder(t: Target) -> tuple[np.ndarray, np.ndarray]:
    """A rock or a heap of debris: a sphere whose radius varies by smooth random bumps at two scales, then
    stretched to length x width x height. Its bumps are seeded by its size alone, so moving, turning or
    burying a boulder (as a differentiable render or a pose sweep does) keeps its shape."""
    directions, faces = _primitive("sphere")  # as many vertices as a sphere
    seed = np.frombuffer(np.array([t.length, t.width, t.height, t.lumpiness]).tobytes(), dtype=np.uint32)
    rng = np.random.default_rng(seed)
    bumps = np.zeros(len(directions))
    for count, width in BOULDER_LUMPS:
        centres = rng.normal(size=(count, 3))
        centres /= np.linalg.norm(centres, axis=1, keepdims=True)
        weights = rng.normal(size=count) * width  # smaller knobs rise less
        bumps += np.exp((directions @ centres.T - 1.0) / width**2) @ weights
    bumps /= max(np.abs(bumps).max(), 1e-12)  # in [-1, 1]: the radius stays in 1 +- lumpiness, above 0
    v = directions * (1.0 + t.lumpiness * bumps)[:, None]
    v = (v - (v.max(0) + v.min(0)) / 2) / (v.max(0) - v.min(0)) * [t.length, t.width, t.height]
    return v, faces


def check_scene(scene: Scene) -> None:
    """What Scene.validate cannot check, so a bad preset fails before a run writes anything: every
    mesh-file target loads and is not buried whole (built-in shapes need no load: Scene.validate
    knows their height), and broadside beams cover the chip in elevation."""
    if scene.sonar.aperture_angle:
        check_elevation_coverage(scene.sonar, 0.75 * scene.sonar.aperture_angle / 2)
    for i, t in enumerate(scene.targets):
        if t.shape == "mesh":
            _checked_shape(t, f"targets[{i}]")


def _checked_shape(t: Target, where: str) -> tuple[np.ndarray, np.ndarray]:
    v, f = _unit_shape(t, where)
    height = v[:, 2].max()
    if t.burial >= height:
        raise SasmiError(f"{where}.burial: {t.burial:g} m buries the whole target (height {height:g} m)")
    return v, f


def target_mesh(t: Target, floor: Surface, chip_size: float, where: str) -> TriangleMesh:
    """The target standing on the seabed at its (x, y), sunk by its burial."""
    v, f = _checked_shape(t, where)
    yaw = math.radians(t.yaw)
    rot = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    ground = float(floor.at(t.x, t.y))
    v = v @ rot.T + [t.x, t.y, ground - t.burial]
    return TriangleMesh((v * (2.0 / chip_size)).astype(np.float32), f, t.albedo, COS_POWER[t.backscatter])


def track_length(sonar) -> float:
    """m of track the emitters spread over: `track_length`, or with an aperture angle as much as the
    chip's far corners need for their full aperture (chip_size + 2 R_far tan(angle / 2))."""
    if not sonar.aperture_angle:
        return sonar.track_length
    far = math.hypot(sonar.near_range + sonar.chip_size, sonar.array_altitude)
    return sonar.chip_size + 2 * far * math.tan(math.radians(sonar.aperture_angle / 2))


def emitter_positions(scene: Scene) -> np.ndarray:
    """Emitters along the track (ground range 0) at `sonar.array_altitude`, in chip units."""
    s = scene.sonar
    scale = 2.0 / s.chip_size
    track_x = -(s.near_range + s.chip_size / 2)
    half = track_length(s) / 2
    ys = np.linspace(-half, half, s.emitters) if s.emitters > 1 else np.zeros(1)
    return np.stack([np.full_like(ys, track_x), ys, np.full_like(ys, s.array_altitude)], 1) * scale


def beam_falloff(positions: np.ndarray, aims: np.ndarray, points: np.ndarray, cutoff: float, beam_width: float
                 ) -> np.ndarray:
    """(N, P) spot profile of each emitter towards each point (P, 3), as Mitsuba's `spot`: 1 within
    beam_width of the axis, linear in the angle to 0 at the cutoff (deg)."""
    axis = aims - positions
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    to_point = points[None, :, :] - positions[:, None, :]  # (N, P, 3)
    return spot_profile(np.einsum("npk,nk->np", to_point, axis) / np.linalg.norm(to_point, axis=2), cutoff, beam_width)


def spot_profile(cos_off_axis: np.ndarray, cutoff: float, beam_width: float) -> np.ndarray:
    """Mitsuba's spot falloff from the cosine of the angle off the beam axis (angles in deg)."""
    angle = np.degrees(np.arccos(np.clip(cos_off_axis, -1, 1)))
    return np.clip((cutoff - angle) / (cutoff - beam_width), 0.0, 1.0)


def exposure(positions: np.ndarray, cos_power: int = 1, beam: tuple | None = None) -> float:
    """1 / radiance of a flat albedo-1 floor at the chip centre lit by unit spots.

    Irradiance from each spot aimed at the centre is I cos(theta) / d^2 (no falloff on
    the beam axis); Lambertian radiance is albedo / pi times the irradiance, and Lambert's
    cos^2 law (cos_power 2) weighs each spot's part by cos(theta) once more. `beam` =
    (aims, cutoff, beam_width) weighs each spot by its profile (spots not aimed at the centre).
    """
    d2 = (positions**2).sum(1)
    cos_theta = positions[:, 2] / np.sqrt(d2)
    weight = 1.0 if beam is None else beam_falloff(positions, beam[0], np.zeros((1, 3)), *beam[1:])[:, 0]
    return float(math.pi / (weight * cos_theta**cos_power / d2).sum())


def flat_floor_irradiance(positions: np.ndarray, size: int, cos_power: int = 1, beam: tuple | None = None
                          ) -> np.ndarray:
    """(size, size) sum of [profile x] cos(theta)^cos_power / d^2 over the emitters, flat floor at pixel centres."""
    # float32 per emitter (a relative error of 1e-7, far below a gray level) halves the time of 32 emitters
    centres = ((np.arange(size) + 0.5) / size * 2 - 1).astype(np.float32)
    total = np.zeros((size, size))
    for k, (px, py, pz) in enumerate(positions.astype(np.float32)):
        d2 = ((px - centres) ** 2)[None, :] + ((py - centres) ** 2 + pz**2)[:, None]  # (rows = y, cols = x)
        cos_theta = pz / np.sqrt(d2)
        part = (cos_theta if cos_power == 1 else cos_theta**cos_power) / d2
        if beam is not None:  # the same as beam_falloff, one emitter at a time on the pixel grid
            ax, ay, az = (beam[0][k] - positions[k]) / np.linalg.norm(beam[0][k] - positions[k])
            along = (ax * (centres - px))[None, :] + (ay * (centres - py) - az * pz)[:, None]
            part *= spot_profile(along / np.sqrt(d2), beam[1], beam[2])
        total += part
    return total


def check_elevation_coverage(sonar, beam_width: float) -> None:
    """Broadside beams are circular: their elevation width is the aperture's, and must span the chip's
    depression angles (near to far edge) around the chip centre, or the chip's edges would go dark."""
    depression = [math.degrees(math.atan2(sonar.array_altitude, x))
                  for x in (sonar.near_range, sonar.near_range + sonar.chip_size / 2, sonar.near_range + sonar.chip_size)]
    spread = max(depression[0] - depression[1], depression[1] - depression[2])
    if spread > beam_width:
        raise SasmiError(f"sonar.aperture_angle: {sonar.aperture_angle:g} deg beams do not cover the chip in elevation "
                         f"(allowed: >= {spread / 0.75 * 2:.3g} deg for this chip, range and altitude)")


def build_geometry(scene: Scene, size: int) -> Geometry:
    s = scene.sonar
    seabed = surface(scene.seafloor, s.chip_size, scene.seed)
    floor = floor_mesh(seabed.grid(size), s.chip_size, scene.seafloor.albedo, COS_POWER[scene.seafloor.backscatter])
    targets = tuple(target_mesh(t, seabed, s.chip_size, f"targets[{i}]") for i, t in enumerate(scene.targets))
    positions = emitter_positions(scene).astype(np.float64)
    broadside = s.aperture_angle > 0
    aims = np.zeros_like(positions)
    if broadside:  # each beam looks across the track at the chip centre's range, from its own place on the track
        aims[:, 1] = positions[:, 1]
    cone = s.aperture_angle / 2 if broadside else s.cone_angle
    if broadside:
        check_elevation_coverage(s, 0.75 * cone)
    beam = (aims, cone, 0.75 * cone) if broadside else None
    return Geometry(
        size=size,
        metres_per_unit=s.chip_size / 2,
        floor=floor,
        targets=targets,
        emitter_positions=positions,
        aims=aims,
        cone_angle=cone,
        beam_width=0.75 * cone,
        emitter_intensity=s.intensity * scene.post.gain * exposure(positions, floor.cos_power, beam),
        broadside=broadside,
        rocks=seabed.rocks,
    )
