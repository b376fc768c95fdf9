"""The render order: chips grouped by structure within a window, with the same files as in index order."""
from __future__ import annotations

import numpy as np

from sasmi.render.geometry import scene_structure
from sasmi.render.mitsuba import Renderer
from sasmi.renderset.order import grouped
from sasmi.renderset.write import RenderJob, render_set
from sasmi.scene.preset import load_preset

from conftest import REPO


def loads(order: list[int], structures: dict[int, tuple]) -> int:
    """How many times a renderer that keeps one scene loads a new one."""
    return sum(1 for a, b in zip([None, *order], order) if a is None or structures[a] != structures[b])


def test_each_window_is_grouped_and_keeps_its_chips():
    structures = {i: "abc"[i % 3] for i in range(12)}
    order = grouped(list(range(12)), structures, window=6)
    assert sorted(order[:6]) == list(range(6)) and sorted(order[6:]) == list(range(6, 12))
    assert order[:6] == [0, 3, 1, 4, 2, 5]
    assert order[6:] == [8, 11, 6, 9, 7, 10]  # the first window's last structure ("c") goes first
    assert loads(order, structures) == 5 and loads(list(range(12)), structures) == 12


def test_a_window_longer_than_the_chips_groups_them_all():
    structures = {i: i % 2 for i in (3, 4, 7, 8, 9)}
    assert grouped([3, 4, 7, 8, 9], structures, window=64) == [3, 7, 9, 4, 8]


def test_grouped_order_writes_what_index_order_renders(tmp_path):
    """Loaded or updated in place, in any order, a chip's render is the same (to float32 rounding: Embree's
    BVH over a loaded scene and over an updated one may sum in another order)."""
    preset = load_preset(REPO / "scenes" / "cylinder_chip.toml")
    scenes = [preset.sample(0, i) for i in range(6)]
    structures = {i: scene_structure(s) for i, s in enumerate(scenes)}
    assert grouped(list(range(6)), structures, 64) != list(range(6))  # the set is written out of index order
    render_set(RenderJob(preset=preset, out=tmp_path / "set", count=6, size=32, spp=4, image_format="npy"),
               progress=False)
    for i, scene in enumerate(scenes):
        alone = Renderer(size=32, spp=4).render(scene).image  # a fresh scene for each chip
        np.testing.assert_allclose(np.load(tmp_path / "set" / "images" / f"{i:06d}.npy"), alone, rtol=0, atol=1e-5)
