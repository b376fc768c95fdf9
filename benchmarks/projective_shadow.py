"""Can Mitsuba's projective integrator differentiate a shadow edge where `sasmi fit-scene` cannot?

The differentiable render uses the `direct` integrator, whose automatic differentiation does not see
visibility: it gets roughness and elevation wrong where shadows move, so those take central differences
(docs/differentiable.md). `direct_projective` adds visibility terms but rejects the orthographic camera
and has none for spot lights. This scene is what it accepts: a box on a plane, a small area emitter at
a grazing angle (its shadow ends on the plane), a distant perspective camera looking straight down.
It prints d(mean brightness) / d(box height) by AD for each integrator and a central difference at the
same sample seed, per seed. Figures: docs/results.md, *Differentiable scenes*.

    .venv/bin/python benchmarks/projective_shadow.py [--seeds 2] [--spp 64]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

HEIGHT = 0.2  # m: the box's height; its shadow, about 1.3 m long, ends on the 8 m plane
STEP = 0.02   # relative step of the central difference
INTEGRATORS = {"direct": {"type": "direct"},
               "direct_projective (octree guiding)": {"type": "direct_projective"},
               "direct_projective (grid guiding)": {"type": "direct_projective", "guiding": "grid"},
               "direct_projective (no guiding)": {"type": "direct_projective", "guiding": "none"}}


def scene_dict(integrator: dict, spp: int) -> dict:
    import mitsuba as mi

    t = mi.ScalarTransform4f

    def diffuse(value: float) -> dict:
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": value}}

    return {
        "type": "scene", "integrator": integrator,
        "sensor": {"type": "perspective", "fov": 2.0, "to_world": t().look_at(origin=[0, 0, 200], target=[0, 0, 0],
                                                                             up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"},
                            "sample_border": True},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "floor": {"type": "rectangle", "to_world": t().scale(4.0), "bsdf": diffuse(0.5)},
        "box": {"type": "cube", "to_world": t().translate([0, 0, HEIGHT / 2]).scale([0.6, 0.6, HEIGHT / 2]),
                "bsdf": diffuse(0.9)},
        "light": {"type": "rectangle", "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 2000.0}},
                  "to_world": t().look_at(origin=[-20, 0, 3], target=[0, 0, 0], up=[0, 0, 1]).scale(0.2)},
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--spp", type=int, default=64)
    args = p.parse_args()
    from sasmi.render.llvm import import_mitsuba

    mi, dr = import_mitsuba()  # sasmi's variant and libLLVM, as every render
    for name, integrator in INTEGRATORS.items():
        scene = mi.load_dict(scene_dict(integrator, args.spp))
        params = mi.traverse(scene)
        base = dr.unravel(mi.Point3f, params["box.vertex_positions"])

        def mean_brightness(relative: float, seed: int, grad: bool = False) -> tuple[float, float]:
            scale = mi.Float(relative)
            if grad:
                dr.enable_grad(scale)
            params["box.vertex_positions"] = dr.ravel(mi.Point3f(base.x, base.y, base.z * (1 + scale)))
            params.update()
            loss = dr.mean(mi.render(scene, params, seed=seed, spp=args.spp), axis=None)
            if grad:
                dr.backward(loss)
            return float(np.array(loss).ravel()[0]), float(np.array(dr.grad(scale)).ravel()[0]) if grad else 0.0

        for seed in range(args.seeds):
            began = time.perf_counter()
            _, ad = mean_brightness(0.0, seed, grad=True)
            seconds = time.perf_counter() - began
            difference = (mean_brightness(STEP, seed)[0] - mean_brightness(-STEP, seed)[0]) / (2 * STEP)
            print(f"{name:36s} seed {seed}: AD {ad:+.3e}, central difference {difference:+.3e}, "
                  f"ratio {ad / difference:6.3f} ({seconds:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
