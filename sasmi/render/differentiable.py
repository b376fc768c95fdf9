"""Differentiable render (`sasmi fit-scene`): scene parameters θ -> image, as a torch function.

Built beside the forward render, not on it: it loads its Mitsuba scenes with the same
`load_scene` and post-processing fields, but each bound scene owns its Mitsuba scene and
the render runs the integrator itself with AD enabled.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from sasmi.errors import SasmiError
from sasmi.render.geometry import Geometry, build_geometry
from sasmi.render.llvm import aligned
from sasmi.render.mitsuba import checked_mitsuba, load_scene, spot_to_world
from sasmi.render.post import post_fields
from sasmi.render.seafloor import surface
from sasmi.render.visibility import pixel_centres
from sasmi.scene.model import Scene

if TYPE_CHECKING:
    import torch

PARAMETERS = ("seafloor.roughness", "seafloor.albedo", "sonar.intensity", "sonar.elevation")
# Parameters that move shadow edges, which Dr.Jit's AD of the `direct` integrator does not see
# (the projective integrators reject the orthographic camera, and spot lights have no edge
# term): their derivative is a central difference of the image at the same sample seed.
FINITE_DIFFERENCE = ("seafloor.roughness", "sonar.elevation")
FD_STEP = 0.01  # relative to the parameter's value


def scene_parameters(scene: Scene) -> np.ndarray:
    """(4,) θ of `scene` in PARAMETERS order: roughness 1 (its own relief), albedo, intensity, altitude (m)."""
    return np.array([1.0, scene.seafloor.albedo, scene.sonar.intensity, scene.sonar.array_altitude])


@dataclass(frozen=True)
class BoundScene:
    """A scene split into the part θ moves and the part that stays, with its own Mitsuba scene.

    Arrays are Dr.Jit Floats, xyz flattened, chip units. Each bound scene owns its Mitsuba
    scene because a render's AD graph does not survive another render of the same Mitsuba
    scene: with two scenes rendered in turn on one, only the second one's gradient reaches
    θ. So K scenes in one loss need K bound scenes, and one bound scene holds one
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
    noise: object  # mi.Float (H·W,): additive offset in gray levels (noise floor x speckle + noise)


class DifferentiableRenderer:
    """θ = (roughness, albedo, intensity, altitude) → chip image, differentiable through Dr.Jit's AD.

    The image is the forward render's: the same `direct` integrator (one emitter sample, no
    BSDF sample), exposure, time-varying gain and, for a BoundScene made with speckle, the
    same speckle and noise draws as fixed fields; then clipped to [0, 1]. For every
    parameter the AD graph of one `direct` render is recorded and differentiated (the
    primal and its gradient share one sample stream, so a gradient is that of the very
    image it came with, which central differences at the same seed check). Dr.Jit's AD does
    not differentiate visibility, so for the parameters that move shadow edges
    (FINITE_DIFFERENCE: roughness, elevation) `image` passes back a central difference of
    the image instead (docs/differentiable.md lists the measured ratios).

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
        self.mi, self.dr = checked_mitsuba(size, spp)
        self.size, self.spp = size, spp
        x, y = pixel_centres(size)
        self._pixel_x, self._pixel_y = self._upload(x), self._upload(y)  # (H·W,) pixel centres, row-major

    def _upload(self, a: np.ndarray):
        return self.mi.Float(aligned(a))

    def _opaque(self, value: float):
        return self.dr.opaque(self.mi.Float, value)

    def bind(self, scene: Scene, speckle: bool = True) -> BoundScene:
        """Split `scene` for `image`; `speckle` keeps the scene's speckle and noise draws as fixed fields.

        The relief is the seabed without its rocks: `seafloor.surface` draws the rough
        surface, then the ripple phase, then the rocks from one generator, so dropping the
        rocks leaves the first two draws and heights = relief + rocks exactly. Scaling
        `rms_height` and `ripple_amplitude` by r scales the relief by r (the rough part is
        normalised to its rms), which is how a fitted roughness goes back into a preset.
        """
        s = scene.sonar
        if s.slant_range:
            raise SasmiError("sonar.slant_range: the differentiable render works in ground range; "
                             "fit a preset with slant_range = false")
        if s.aperture_angle:
            raise SasmiError("sonar.aperture_angle: the differentiable render models spots aimed at the chip "
                             "centre; fit a preset with aperture_angle = 0")
        unit = 2.0 / s.chip_size  # chip units per metre
        g = build_geometry(scene, self.size)
        relief = surface(dataclasses.replace(scene.seafloor, rocks=0), s.chip_size, scene.seed)
        floor_relief = np.zeros_like(g.floor.vertices)
        floor_relief[:, 2] = relief.grid(self.size).ravel() * unit
        lifts = tuple(float(relief.at(t.x, t.y)) * unit for t in scene.targets)
        fields = post_fields(scene, self.size) if speckle else (np.ones((self.size, self.size)),
                                                                np.full((self.size, self.size), scene.post.noise_floor))
        mitsuba_scene = load_scene(self.mi, self.dr, g, self.spp)
        return BoundScene(
            scene=scene, geometry=g, mitsuba_scene=mitsuba_scene, params=self.mi.traverse(mitsuba_scene),
            floor_fixed=self._upload(g.floor.vertices - floor_relief),
            floor_relief=self._upload(floor_relief),
            floor_up=self._upload(np.tile([0.0, 0.0, 1.0], len(g.floor.vertices))),
            targets_fixed=tuple(self._upload(m.vertices - [0.0, 0.0, lift]) for m, lift in zip(g.targets, lifts)),
            targets_up=tuple(self._upload(np.tile([0.0, 0.0, 1.0], len(m.vertices))) for m in g.targets),
            targets_lift=lifts, speckle=self._upload(fields[0]), noise=self._upload(fields[1]))

    def image(self, bound: BoundScene, theta: "torch.Tensor", seed: int, wrt: Sequence[str] = PARAMETERS
              ) -> "torch.Tensor":
        """(H, W) float32 in [0, 1] from θ (4,) in PARAMETERS order; gradients flow back to θ in torch.

        For the parameters in `wrt` that are in FINITE_DIFFERENCE the gradient is the central
        difference of the image (two more renders each, at the same seed, done first: a
        render on the bound scene after the differentiable one would drop its graph); the
        others' come from Dr.Jit's AD. The image itself is the same either way.
        """
        import torch

        assert theta.shape == (len(PARAMETERS),), theta.shape
        theta = theta.float()
        slopes = {}
        if theta.requires_grad:
            for name in FINITE_DIFFERENCE:
                if name in wrt:
                    slopes[PARAMETERS.index(name)] = self._difference(bound, theta.detach(), name, seed)
        fd = torch.tensor([i in slopes for i in range(len(PARAMETERS))])
        image = self._wrapped(bound, torch.where(fd, theta.detach(), theta), seed)
        for i, slope in slopes.items():
            image = image + (theta[i] - theta[i].detach()) * slope  # value unchanged, d/dθ_i = slope
        return image

    def _wrapped(self, bound: BoundScene, theta: "torch.Tensor", seed: int) -> "torch.Tensor":
        @self.dr.wrap(source="torch", target="drjit")
        def render(theta_dr):
            return self._image(bound, theta_dr.array, seed)

        return render(theta)

    def _difference(self, bound: BoundScene, theta: "torch.Tensor", name: str, seed: int) -> "torch.Tensor":
        """(H, W) central difference d image / d θ[name] at `seed` (common random numbers)."""
        import torch

        i = PARAMETERS.index(name)
        step = FD_STEP * max(abs(float(theta[i])), 1e-3)
        with torch.no_grad():
            plus, minus = theta.clone(), theta.clone()
            plus[i] += step
            minus[i] -= step
            return (self._wrapped(bound, plus, seed) - self._wrapped(bound, minus, seed)) / (2 * step)

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
        # 0.0 can resize the literal operand in place).
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
            p[f"emitter_{k}.to_world"] = spot_to_world(mi, position, aim)
        power = g.floor.cos_power
        centre = self._irradiance(g.emitter_positions, height, 0.0, 0.0, power)
        p["emitter_0.intensity.value"] = intensity * self._opaque(b.scene.post.gain * np.pi) / centre  # exposure
        p.update()

        scene = b.mitsuba_scene
        radiance = scene.integrator().render(scene, scene.sensors()[0], seed=seed % 2**31, spp=self.spp,
                                             develop=True, evaluate=False).array  # (H·W,) row-major
        post = b.scene.post
        if post.tvg:  # post.tvg_gain
            gain = centre / self._irradiance(g.emitter_positions, height, self._pixel_x, self._pixel_y, power)
            radiance = radiance * (gain if post.tvg_strength == 1 else dr.power(gain, post.tvg_strength))
        image = dr.clip(radiance * b.speckle + b.noise, 0.0, 1.0)
        return mi.TensorXf(image, shape=(self.size, self.size))

    def _irradiance(self, positions: np.ndarray, height, x, y, cos_power: int = 1):
        """Σ over the emitters of cos^p θ / d² on a flat floor at (x, y), the array at `height` (chip units)."""
        dr = self.dr
        total = 0.0
        for px, py in positions[:, :2].tolist():
            d2 = dr.square(self._opaque(px) - x) + dr.square(self._opaque(py) - y) + dr.square(height)
            cos_theta = height / dr.sqrt(d2)
            total = total + (cos_theta if cos_power == 1 else dr.power(cos_theta, cos_power)) / d2
        return total
