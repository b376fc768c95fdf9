"""Which target each pixel sees, and which target hides it from the array: ray casts for the masks.

Camera rays through pixel centres find the visible surface in the rendered Mitsuba scene
(one preliminary intersection: shape and height, queued right behind the render's kernel);
from each floor hit, rays towards SHADOW_PROBES emitters spread over the array are traced
against the targets alone (`Occluders`), so a ripple between a floor point and a target
does not punch a hole in that target's acoustic shadow. A floor point hidden by a target
from at least SHADOW_FRACTION of the probes is acoustic shadow.
"""
from __future__ import annotations

import numpy as np

from sasmi.render.geometry import Geometry, TriangleMesh, beam_falloff
from sasmi.render.llvm import aligned

CAMERA_HEIGHT = 50.0  # chip units above the floor; far above any target
SHADOW_FRACTION = 0.5  # a floor point is in acoustic shadow when a target hides it from half the array
SHADOW_PROBES = 8  # emitters, evenly spread over the array, that the shadow mask is tested against
APERTURE_PROBES = 24  # with broadside beams (sonar.aperture_angle) only some probes light each point


def mi_mesh(mi, name: str, mesh: TriangleMesh):
    """A Mitsuba mesh holding `mesh`'s triangles (no BSDF set)."""
    m = mi.Mesh(name, vertex_count=len(mesh.vertices), face_count=len(mesh.faces), has_vertex_normals=False)
    params = mi.traverse(m)
    params["vertex_positions"] = aligned(mesh.vertices)
    params["faces"] = aligned(mesh.faces, np.uint32)
    params.update()
    return m


def shape_ids(mi, dr, scene, count: int) -> np.ndarray:
    """(count,) Mitsuba registry ids of the shapes named target_0 .. target_{count-1} in `scene`."""
    by_name = {s.id(): s for s in scene.shapes()}
    return np.array([dr.reinterpret_array(mi.UInt32, mi.ShapePtr(by_name[f"target_{k}"]))[0]
                     for k in range(count)], dtype=np.int64)


def index_of(ids: np.ndarray, target_ids: np.ndarray) -> np.ndarray:
    """Map Mitsuba shape registry ids to target indices (-1 for floor or miss)."""
    out = np.full(ids.shape, -1, dtype=np.int64)
    for k, sid in enumerate(target_ids):
        out[ids == sid] = k
    return out


def shadow_probes(count: int, probes: int = SHADOW_PROBES) -> np.ndarray:
    """Indices of `probes` emitters spread evenly over the array (all of them if there are fewer)."""
    if count <= probes:
        return np.arange(count)
    return np.round(np.linspace(0, count - 1, probes)).astype(int)


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


class Occluders:
    """The targets alone, as a Mitsuba scene of their own, updated in place like the rendered scene."""

    def __init__(self, mi, dr, g: Geometry):
        self.mi, self.dr = mi, dr
        self.scene = mi.load_dict({"type": "scene", **{f"target_{k}": mi_mesh(mi, f"target_{k}", t)
                                                       for k, t in enumerate(g.targets)}})
        self.params = mi.traverse(self.scene)
        self.ids = shape_ids(mi, dr, self.scene, len(g.targets))

    def update(self, g: Geometry) -> None:
        for k, t in enumerate(g.targets):
            self.params[f"target_{k}.vertex_positions"] = aligned(t.vertices)
            self.params[f"target_{k}.faces"] = aligned(t.faces, np.uint32)
        if g.targets:
            self.params.update()

    def first_hit(self, origins: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """(R,) index of the first target on each segment origin -> end, (R, 3) each; -1 for none."""
        mi, dr = self.mi, self.dr
        to_end = ends - origins
        dist = np.linalg.norm(to_end, axis=1)
        directions = to_end / dist[:, None]
        # Positions travel as array data, not as kernel literals: one compiled kernel serves every scene.
        rays = mi.Ray3f(mi.Point3f(*(aligned(origins[:, i]) for i in range(3))),
                        mi.Vector3f(*(aligned(directions[:, i]) for i in range(3))))
        hits = self.scene.ray_intersect_preliminary(mi.Ray3f(rays, mi.Float(aligned(dist * (1 - 1e-4)))))
        return index_of(np.asarray(dr.reinterpret_array(mi.UInt32, hits.shape), dtype=np.int64), self.ids)


def pixel_centres(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, n) x and y (chip units) of the pixel centres of an n x n chip; row = y, col = x."""
    centres = (np.arange(n) + 0.5) / n * 2 - 1
    return np.meshgrid(centres, centres)


def mask_pixels(g: Geometry) -> np.ndarray:
    """(H*W,) bool: the pixels whose camera hit the masks use, about a tenth of a chip: those under a
    target's footprint (the camera looks straight down, so no other pixel can see a target) and the
    shadow candidates (the only floor points the shadow rays start from)."""
    xs, ys = pixel_centres(g.size)
    points = np.stack([xs.ravel(), ys.ravel()], 1)
    needed = shadow_candidates(g, points)
    for t in g.targets:
        low, high = t.vertices[:, :2].min(0), t.vertices[:, :2].max(0)
        needed |= ((points >= low) & (points <= high)).all(1)
    return needed


def camera_hits(mi, dr, scene, n: int, pixels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(n*n,) int64 Mitsuba shape registry id (0 for a miss) and float64 height (chip units) of the surface
    seen through each pixel centre, straight down, row-major; only at `pixels` ((n*n,) bool) when given,
    id 0 and height NaN elsewhere.

    One preliminary intersection gives both: the masks need which shape and where, not the full
    SurfaceInteraction, and evaluating the two outputs together traces the rays once (reading
    them one after the other would launch the ray-tracing kernel once per output).
    """
    xs, ys = (c.ravel() for c in pixel_centres(n))
    if pixels is not None:
        if not pixels.any():  # a chip without targets: nothing to trace (Dr.Jit aborts on empty rays)
            return np.zeros(n * n, dtype=np.int64), np.full(n * n, np.nan)
        xs, ys = xs[pixels], ys[pixels]
    origin = mi.Point3f(aligned(xs), aligned(ys), aligned(np.full(len(xs), CAMERA_HEIGHT)))
    pi = scene.ray_intersect_preliminary(mi.Ray3f(origin, mi.Vector3f(0, 0, -1)))
    ids, heights = dr.reinterpret_array(mi.UInt32, pi.shape), CAMERA_HEIGHT - pi.t
    dr.eval(ids, heights)
    if pixels is None:
        return np.asarray(ids, dtype=np.int64), np.asarray(heights, dtype=np.float64)
    all_ids, all_heights = np.zeros(n * n, dtype=np.int64), np.full(n * n, np.nan)
    all_ids[pixels], all_heights[pixels] = np.asarray(ids), np.asarray(heights)
    return all_ids, all_heights


def visibility(ids: np.ndarray, heights: np.ndarray, target_ids: np.ndarray, occluders: Occluders, g: Geometry
               ) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) int64 each: index of the visible target (-1 none) and of the target shadowing the pixel (-1 none).

    `ids` and `heights` (H*W,) are `camera_hits` of the rendered Mitsuba scene of `g` (at `mask_pixels(g)`
    or more), `target_ids` its targets' registry ids.
    """
    n = g.size
    visible = index_of(ids, target_ids)
    xs, ys = pixel_centres(n)
    # lifted off the floor (only floor points are tested) so the shadow rays do not start inside it
    lifted = np.stack([xs.ravel(), ys.ravel(), heights + 1e-4], 1).astype(np.float32)  # (P, 3)
    probes = shadow_probes(len(g.emitter_positions), APERTURE_PROBES if g.broadside else SHADOW_PROBES)
    emitters = g.emitter_positions[probes].astype(np.float32)  # (K, 3)
    owner = np.full(n * n, -1, dtype=np.int64)
    traced = np.nonzero(np.isfinite(heights) & (visible < 0))[0]
    candidates = traced[shadow_candidates(g, lifted[traced])]
    if candidates.size:
        points = lifted[candidates]
        # with broadside beams a probe counts as much as it lights the point; else every probe counts 1
        weights = (beam_falloff(g.emitter_positions[probes], g.aims[probes], points.astype(np.float64),
                                g.cone_angle, g.beam_width) if g.broadside else np.ones((len(probes), len(points))))
        # one launch for all probes, probe-major: (K * C, 3)
        blocker = occluders.first_hit(np.tile(points, (len(emitters), 1)), np.repeat(emitters, len(points), axis=0))
        counts = np.zeros((len(g.targets) + 1, len(points)))  # row 0: nothing in the way
        for per_probe, weight in zip(blocker.reshape(len(emitters), len(points)), weights):
            counts[per_probe + 1, np.arange(len(points))] += weight  # one blocker per point: no repeats
        blocked = counts[1:]
        lit = weights.sum(axis=0)
        owner[candidates] = np.where((blocked.max(axis=0) >= SHADOW_FRACTION * lit) & (lit > 0),
                                     blocked.argmax(axis=0), -1)
    owner = np.where(visible >= 0, -1, owner)
    return visible.reshape(n, n), owner.reshape(n, n)
