"""The order a process renders its chips in: grouped by structure, so its Mitsuba scene is mostly updated.

A renderer keeps one loaded scene and updates it in place for a chip of the same structure
(`sasmi.render.geometry.scene_structure`); a chip of another structure loads a new one, which costs
more. A chip's output depends on its index alone (to float32 rounding), so the order is free to choose.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from sasmi.scene.model import Scene

RENDER_WINDOW = 64  # untransformed chips are grouped by structure this many at a time (a transform's: a batch)


def grouped(todo: list[int], structures: dict[int, tuple], window: int) -> list[int]:
    """`todo` with each run of `window` chips ordered by structure (the previous run's last one first), so the
    renderer loads a Mitsuba scene once per structure in a run and updates it in place for the rest (in index
    order, `cylinder_chip`'s chips of 1, 2 and 3 targets alternate and half of them would load one). Each run
    keeps its own chips, so a transform's batch of `window` chips is the same set in either order."""
    ordered, last = [], None
    for start in range(0, len(todo), window):
        run = todo[start:start + window]
        rank = {}  # structure -> its rank in the run: groups keep the order of their first chips
        for index in run:
            rank.setdefault(structures[index], len(rank))
        if last in rank:
            rank[last] = -1
        ordered += sorted(run, key=lambda index: rank[structures[index]])  # stable: index order within a group
        last = structures[ordered[-1]]
    return ordered


def render_grouped(scenes: list[Scene], size: int, spp: int) -> np.ndarray:
    """(N, size, size) float32: the scenes' images in their order, rendered grouped by structure."""
    from sasmi.render.geometry import scene_structure
    from sasmi.render.mitsuba import render

    images = np.empty((len(scenes), size, size), dtype=np.float32)
    indices = list(range(len(scenes)))
    for i in grouped(indices, {i: scene_structure(scene) for i, scene in enumerate(scenes)}, max(len(scenes), 1)):
        images[i] = render(scenes[i], size, spp).image
    return images
