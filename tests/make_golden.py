"""Makes tests/golden/cylinder_32.npy. Rerun by hand only after a deliberate change to the render model:
    .venv/bin/python tests/make_golden.py
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from sasmi.render.mitsuba import Renderer
from sasmi.scene.model import Post, Scene, Seafloor, Sonar, Target


def golden_image() -> np.ndarray:
    scene = Scene(sonar=Sonar(near_range=40.0), seafloor=Seafloor(rms_height=0.01, ripple_amplitude=0.005),
                  targets=(Target(x=-0.8, y=0.2, yaw=60.0, burial=0.1),), post=Post(speckle_looks=0.0, noise_std=0.0),
                  seed=1234).validate()
    return Renderer(size=32, spp=64).render(scene).image


if __name__ == "__main__":
    path = Path(__file__).parent / "golden" / "cylinder_32.npy"
    np.save(path, golden_image())
    print(f"wrote {path}")
