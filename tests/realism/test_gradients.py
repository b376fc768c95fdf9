"""The differentiable render's gradients, proven against an independent central difference.

Per scene and parameter, the gradient `DifferentiableRenderer.image` passes back (Dr.Jit's AD for
albedo and intensity; a 1 % central difference of the image for roughness and elevation) is averaged
over SEEDS sample seeds and compared with a central difference of the loss at another step (3 %),
averaged over the same seeds. One seed's ratio moves by tens of percent where shadow edges cross
samples; the average is what makes a 10 % tolerance honest, and a gradient 1.25 x too large or too
small fails it. Loss: the chip's mean brightness.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from sasmi.realism.fit_scene import central_difference
from sasmi.render.differentiable import PARAMETERS, DifferentiableRenderer, scene_parameters
from sasmi.scene.preset import Preset

SIZE, SPP, SEEDS = 64, 16, 12
REFERENCE_STEP = 0.03  # relative; the render's own difference uses 1 %
TOLERANCE = 0.10
SCENES = {
    "flat_floor": {"seafloor": {"rms_height": 0.005, "correlation_length": 0.4}},
    "rough_floor": {"seafloor": {"rms_height": 0.02, "correlation_length": 0.3, "ripple_amplitude": 0.01,
                                 "ripple_wavelength": 0.8}},
    "floor_with_target": {"seafloor": {"rms_height": 0.02, "correlation_length": 0.3, "ripple_amplitude": 0.01,
                                       "ripple_wavelength": 0.8},
                          "targets": [{"shape": "cylinder", "x": -0.8, "y": 0.2, "yaw": 60.0, "radius": 0.3}]},
}


@pytest.fixture(scope="module")
def renderer() -> DifferentiableRenderer:
    return DifferentiableRenderer(SIZE, SPP)


def averaged_gradients(renderer, raw: dict) -> tuple[np.ndarray, np.ndarray]:
    """(4,) passed-back and (4,) reference gradients of the mean brightness, each averaged over SEEDS."""
    scene = Preset.from_dict({"sonar": {"near_range": 30.0, "emitters": 16}, **raw,
                              "post": {"speckle_looks": 0.0, "noise_std": 0.0}}).sample(0, 0)
    bound = renderer.bind(scene, speckle=False)
    theta0 = scene_parameters(scene)
    passed, reference = np.zeros(len(PARAMETERS)), np.zeros(len(PARAMETERS))
    for seed in range(SEEDS):
        theta = torch.tensor(theta0, dtype=torch.float32, requires_grad=True)
        renderer.image(bound, theta, seed).mean().backward()
        passed += theta.grad.numpy()
        with torch.no_grad():
            for i in range(len(PARAMETERS)):
                reference[i] += central_difference(lambda x: renderer.image(bound, torch.tensor(x), seed).mean().item(),
                                                   theta0, i, REFERENCE_STEP * theta0[i])
    return passed / SEEDS, reference / SEEDS


@pytest.mark.parametrize("scene", SCENES)
def test_every_gradient_within_ten_percent_of_a_central_difference(renderer, scene):
    passed, reference = averaged_gradients(renderer, SCENES[scene])
    ratios = passed / reference
    print(scene, dict(zip(PARAMETERS, np.round(ratios, 3))))
    for name, ratio in zip(PARAMETERS, ratios):
        assert abs(ratio - 1) < TOLERANCE, f"{scene}: {name} passed back {ratio:.3f} x the central difference"
