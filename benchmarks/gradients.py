"""Gradients of the differentiable render against central differences, per parameter and scene.

Loss: mean brightness of the chip. `ad` is the gradient `DifferentiableRenderer.image` passes
back to θ (Dr.Jit's AD for albedo and intensity; for parameters that move visibility,
roughness and elevation, a central difference of the image, chained through the loss:
`differentiable.FINITE_DIFFERENCE`); `ad_only` is what Dr.Jit's AD alone gives; `fd` is a
central difference of the loss with a different step (2 % of θ instead of the render's 1 %),
all at one sample seed. Scenes: `flat_floor` (sand with 5 mm rms relief: an exactly flat
floor has no relief to scale) and `rough_floor_cyl` (2 cm rms relief, 1 cm ripples, a
cylinder: the floor and the cylinder shadow it).

    .venv/bin/python benchmarks/gradients.py [--size 64] [--spp 16] [--seeds 3]
"""
from __future__ import annotations

import argparse

import numpy as np

SCENES = {
    "flat_floor": {"seafloor": {"rms_height": 0.005, "correlation_length": 0.4}, "targets": []},
    "rough_floor_cyl": {"seafloor": {"rms_height": 0.02, "correlation_length": 0.3, "ripple_amplitude": 0.01,
                                     "ripple_wavelength": 0.8},
                        "targets": [{"shape": "cylinder", "x": -0.8, "y": 0.2, "yaw": 60.0, "radius": 0.3}]},
}
PARAMS = ("seafloor.roughness", "seafloor.albedo", "sonar.intensity", "sonar.elevation")
REFERENCE_STEP = 0.02  # relative step of the reference central difference


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=3, help="sample seeds per scene; ratios are of the sums")
    args = ap.parse_args()

    import torch

    from sasmi.realism.fit_scene import central_difference
    from sasmi.render.differentiable import PARAMETERS, DifferentiableRenderer, scene_parameters
    from sasmi.scene.preset import Preset

    renderer = DifferentiableRenderer(args.size, args.spp)
    for scene_name, raw in SCENES.items():
        preset = Preset.from_dict({"sonar": {"near_range": 30.0, "emitters": 16}, **raw,
                                   "post": {"speckle_looks": 0.0, "noise_std": 0.0}})
        scene = preset.sample(0, 0)
        bound = renderer.bind(scene, speckle=False)
        theta0 = scene_parameters(scene)
        for name in PARAMS:
            i = PARAMETERS.index(name)
            sums = np.zeros(3)  # ad, ad_only, fd
            for seed in range(args.seeds):
                grads = []
                for wrt in ((name,), ()):  # () : no finite differences, Dr.Jit's AD alone
                    theta = torch.tensor(theta0, dtype=torch.float32, requires_grad=True)
                    renderer.image(bound, theta, seed, wrt=wrt).mean().backward()
                    grads.append(theta.grad[i].item())
                with torch.no_grad():
                    fd = central_difference(lambda x: renderer.image(bound, torch.tensor(x), seed).mean().item(),
                                            theta0, i, REFERENCE_STEP * theta0[i])
                sums += [grads[0], grads[1], fd]
            ad, ad_only, fd = sums / args.seeds
            print(f"param={name} scene={scene_name} ad={ad:.5g} fd={fd:.5g} ratio={ad / fd:.3f} "
                  f"ad_only={ad_only:.5g} ad_only_ratio={ad_only / fd:.3f}", flush=True)


if __name__ == "__main__":
    main()
