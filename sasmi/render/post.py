"""The sonar's image formation after the render: time-varying gain, speckle, additive noise.

Radiance (H, W), exposure folded in, goes to a chip in [0, 1] as
    clip(radiance * gain * speckle + noise, 0, 1)
The maps are numpy and depend only on the scene, so `Renderer.render` computes them while
the Mitsuba kernel runs, and the differentiable render reuses the same speckle and noise.
"""
from __future__ import annotations

import math

import numpy as np

from sasmi.render.geometry import Geometry, exposure, flat_floor_irradiance
from sasmi.scene import Scene

Maps = tuple[np.ndarray, np.ndarray, np.ndarray]  # (H, W) float64 each: gain, speckle, noise


def tvg_gain(positions: np.ndarray, size: int) -> np.ndarray:
    """(size, size) gain that makes a flat floor equally bright everywhere, 1 at the chip centre."""
    return (math.pi / exposure(positions)) / flat_floor_irradiance(positions, size)


def post_fields(scene: Scene, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) speckle (gamma, mean 1; all 1 when off) and additive noise (gray levels; 0 when off), seeded by `scene`."""
    post = scene.post
    rng = np.random.default_rng([scene.seed, 11])
    speckle = np.ones((size, size))
    noise = np.zeros((size, size))
    if post.speckle_looks > 0:
        speckle = rng.gamma(post.speckle_looks, 1.0 / post.speckle_looks, size=(size, size))
    if post.noise_std > 0:
        noise = rng.normal(0.0, post.noise_std, size=(size, size))
    return speckle, noise


def post_maps(scene: Scene, g: Geometry) -> Maps:
    """(H, W) time-varying gain (1 when off), speckle (gamma, mean 1) and additive noise of `scene`."""
    gain = tvg_gain(g.emitter_positions, g.size) if scene.post.tvg else np.ones((g.size, g.size))
    return (gain, *post_fields(scene, g.size))


def postprocess(radiance: np.ndarray, maps: Maps) -> np.ndarray:
    """(H, W) radiance -> (H, W) float32 chip in [0, 1]: radiance x gain x speckle + noise, clipped."""
    gain, speckle, noise = maps
    return np.clip(radiance.astype(np.float64) * gain * speckle + noise, 0.0, 1.0).astype(np.float32)
