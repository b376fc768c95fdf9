"""The Mitsuba renderer: determinism, masks and labels that agree with the image, golden image."""
from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from sasmi.errors import SasmiError
from sasmi.render.annotate import MASK_SHADOW, MASK_TARGET
from sasmi.render.mitsuba import Renderer
from sasmi.scene.preset import Preset, load_preset
from sasmi.scene.model import Post, Scene, Sonar, Target

from conftest import REPO, assert_matches_golden

QUIET = Post(speckle_looks=0.0, noise_std=0.0)


@pytest.fixture(scope="module")
def renderer64():
    return Renderer(size=64, spp=16)


def one_cylinder(x=-0.5, y=0.0, yaw=30.0, burial=0.05, **post) -> Scene:
    return Scene(sonar=Sonar(near_range=35.0), targets=(Target(x=x, y=y, yaw=yaw, burial=burial),),
                 post=dataclasses.replace(QUIET, **post), seed=5).validate()


def test_size_must_be_multiple_of_16():
    with pytest.raises(SasmiError, match="size: 40 is not a multiple of 16"):
        Renderer(size=40)


def test_same_scene_same_result(renderer64):
    scene = load_preset(REPO / "scenes" / "muscle_paper.toml").sample(0, 3)
    a = renderer64.render(scene)
    renderer64.render(load_preset(REPO / "scenes" / "seafloor_only.toml").sample(0, 1))  # something else between
    b = renderer64.render(scene)
    assert np.abs(a.image - b.image).max() <= 1 / 255
    assert np.array_equal(a.mask, b.mask)
    assert a.labels == b.labels


def test_masks_and_labels_agree_with_the_image(renderer64):
    scene = one_cylinder()
    out = renderer64.render(scene)
    image, mask = out.image, out.mask
    floor = image[mask == 0]
    shadow = image[mask == MASK_SHADOW]
    target = image[mask == MASK_TARGET]
    assert shadow.size > 20 and target.size > 10
    # shadow pixels are dark (the penumbra still sees up to half the array), the lit target is bright
    assert shadow.mean() < 0.35 * floor.mean()
    assert np.percentile(target, 90) > 2 * floor.mean()
    # the shadow lies on the far side of the target from the track (the track is off the left edge)
    cols = np.arange(image.shape[1])[None, :].repeat(image.shape[0], 0)
    assert cols[mask == MASK_SHADOW].mean() > cols[mask == MASK_TARGET].mean()
    # the label's box contains the highlight (the brightest pixels of the chip)
    label = out.labels["targets"][0]
    c0, r0, c1, r1 = label["bbox"]
    rows, cols_ = np.unravel_index(np.argsort(image, axis=None)[-10:], image.shape)
    assert np.all((c0 <= cols_) & (cols_ < c1) & (r0 <= rows) & (rows < r1))
    # the label's centre is where the target is: inside its box, near the mask centroid
    cx, cy = label["pixel_centre"]
    assert c0 <= cx < c1 and r0 <= cy < r1
    rr, cc = np.nonzero(mask == MASK_TARGET)
    assert abs(cc.mean() - cx) < 3 and abs(rr.mean() - cy) < 3


def test_target_moves_with_its_label(renderer64):
    """Image convention: range to the right (x -> column), along-track down (y -> row)."""
    left_up = renderer64.render(one_cylinder(x=-1.5, y=-1.5, yaw=0))
    right_down = renderer64.render(one_cylinder(x=0.5, y=1.5, yaw=0))
    for out in (left_up, right_down):
        rr, cc = np.nonzero(out.mask == MASK_TARGET)
        cx, cy = out.labels["targets"][0]["pixel_centre"]
        assert abs(cc.mean() - cx) < 2 and abs(rr.mean() - cy) < 2
    assert left_up.labels["targets"][0]["pixel_centre"][0] < 20 < right_down.labels["targets"][0]["pixel_centre"][0]


def test_burial_hides_the_target(renderer64):
    shallow = renderer64.render(one_cylinder(burial=0.0))
    deep = renderer64.render(one_cylinder(burial=0.5))
    # 0.5 m of a 0.6 m cylinder buried: the exposed chord is 0.44 m wide instead of 0.6 m
    assert (deep.mask == MASK_TARGET).sum() < 0.85 * (shallow.mask == MASK_TARGET).sum()
    assert (deep.mask == MASK_SHADOW).sum() < 0.25 * (shallow.mask == MASK_SHADOW).sum()


def test_other_shapes_and_mesh_file(tmp_path, renderer64):
    import trimesh

    trimesh.creation.box(extents=[1.0, 0.6, 0.5]).export(tmp_path / "box.obj")
    preset = Preset.from_dict({"targets": [{"shape": "sphere", "x": -1.5, "y": -1.5, "radius": 0.4},
                                           {"shape": "cone", "x": -1.5, "y": 1.5, "length": 0.8, "radius": 0.5},
                                           {"shape": "mesh", "mesh": "box.obj", "x": 0.0, "y": 0.0, "yaw": 20}],
                               "post": {"speckle_looks": 0.0, "noise_std": 0.0}}, path=tmp_path / "p.toml")
    out = renderer64.render(preset.sample(0, 0))
    for label in out.labels["targets"]:
        assert label["visible_pixels"] > 5 and label["shadow_pixels"] > 5, label["shape"]


def test_speckle_and_noise_are_seeded(renderer64):
    noisy = one_cylinder(speckle_looks=4.0, noise_std=0.05)
    a, b = renderer64.render(noisy), renderer64.render(noisy)
    quiet = renderer64.render(one_cylinder())
    assert np.abs(a.image - b.image).max() <= 1 / 255
    floor = quiet.mask == 0
    assert a.image[floor].std() > 2 * quiet.image[floor].std()


def test_golden_32px():
    """32x32 render of a fixed scene against tests/golden/cylinder_32.npy (made by tests/make_golden.py)."""
    from make_golden import golden_image

    assert_matches_golden("cylinder_32", golden_image(), mean_tol=0.01, max_tol=0.12)


def test_wrong_llvm_library_is_one_line(tmp_path):
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"}
    proc = subprocess.run([sys.executable, "-m", "sasmi.cli.main", "render", str(REPO / "scenes" / "cylinder_chip.toml"),
                           "--out", str(tmp_path / "o"), "--count", "1", "--size", "32"],
                          env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "apt-get install libllvm19" in lines[0]


def test_next_scene_reuses_the_compiled_kernels():
    import drjit as dr

    preset = load_preset(REPO / "scenes" / "cylinder_chip.toml")
    first, second = preset.sample(1, 2), preset.sample(1, 5)  # a cylinder, then a block, neither with companions
    assert first.targets[0].shape != second.targets[0].shape and first.sonar.cone_angle != second.sonar.cone_angle
    assert len(first.targets) == len(second.targets) == 1  # another count of targets is another scene
    renderer = Renderer(size=32, spp=4)
    renderer.render(first)
    loaded = renderer.mitsuba_scene
    dr.kernel_history()  # drop what the first scene compiled
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        renderer.render(second)  # new heightfield, kind of target, cone angle: an update of the same scene
        kernels = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert renderer.mitsuba_scene is loaded
    assert kernels and all(k["cache_hit"] for k in kernels)


def test_masks_from_the_traced_pixels_equal_masks_from_every_pixel(renderer64):
    """A render traces camera rays only where a mask can need them (`mask_pixels`); every pixel gives the same."""
    from sasmi.render.geometry import build_geometry

    preset = load_preset(REPO / "scenes" / "cylinder_chip.toml")
    for index in range(4):
        scene = preset.sample(2, index)
        out = renderer64.render(scene)
        visible, owner = renderer64.visibility(build_geometry(scene, 64), renderer64.camera_hits())
        assert (visible >= 0).any() and (owner >= 0).any()
        assert np.array_equal(out.instances, visible + 1) and np.array_equal(out.shadows, owner + 1)


def test_a_scene_updated_in_place_renders_as_a_fresh_one():
    """A cylinder chip after a torus chip: the update must bring the new triangles, cone and pose along."""
    preset = load_preset(REPO / "scenes" / "cylinder_chip.toml")
    before, scene = preset.sample(0, 0), preset.sample(0, 1)
    assert before.targets[0].shape != scene.targets[0].shape
    # a beam narrow enough to darken the chip's ends, after a wide one that lights it all
    before = dataclasses.replace(before, sonar=dataclasses.replace(before.sonar, cone_angle=45.0))
    scene = dataclasses.replace(scene, sonar=dataclasses.replace(scene.sonar, cone_angle=20.0))
    renderer = Renderer(size=32, spp=4)
    renderer.render(before)
    updated = renderer.render(scene)
    fresh = Renderer(size=32, spp=4).render(scene)
    assert np.array_equal(updated.mask, fresh.mask) and np.array_equal(updated.shadows, fresh.shadows)
    assert np.abs(updated.image - fresh.image).max() <= 1 / 255


def test_two_workers_match_one(tmp_path, render_set):
    from sasmi.cli.main import main

    out = tmp_path / "two"
    assert main(["render", str(REPO / "scenes" / "muscle_paper.toml"), "--out", str(out), "--count", "4",
                 "--size", "32", "--spp", "4", "--workers", "2"]) == 0
    from PIL import Image

    for i in range(4):
        name = f"{i:06d}.png"
        a = np.asarray(Image.open(out / "images" / name), dtype=int)
        b = np.asarray(Image.open(render_set / "images" / name), dtype=int)
        assert np.abs(a - b).max() <= 1
        assert np.array_equal(np.asarray(Image.open(out / "masks" / name)), np.asarray(Image.open(render_set / "masks" / name)))


def test_one_call_api_reuses_one_renderer_per_size():
    """`sasmi.render(scene)` renders and `sasmi.render` is still the package; renderers are cached per (size, spp)."""
    import sasmi
    import sasmi.render.mitsuba as mitsuba
    from sasmi import render

    assert render is sasmi.render and sasmi.render.Renderer is mitsuba.Renderer
    scene = one_cylinder()
    a = sasmi.render(scene, size=32, spp=4)
    assert mitsuba.renderer_for(32, 4) is mitsuba.renderer_for(32, 4)
    assert mitsuba.renderer_for(32, 4) is not mitsuba.renderer_for(48, 4)
    assert np.abs(sasmi.render(scene, size=32, spp=4).image - a.image).max() <= 1 / 255
    assert a.labels["targets"][0]["shadow_pixels"] == a.label.targets[0].shadow_pixels > 0


def test_rocks_are_labelled_clutter_whose_boxes_hold_them(renderer64):
    """Every raised or bright pixel of a flat floor with rocks lies in a rock's box; each box is on its rock."""
    from sasmi.labels import ChipLabel
    from sasmi.scene.model import Seafloor

    scene = Scene(sonar=Sonar(near_range=35.0), seafloor=Seafloor(rms_height=0.0, ripple_amplitude=0.0, rocks=6,
                                                                  rock_radius=0.3), post=QUIET, seed=8).validate()
    out = renderer64.render(scene)
    clutter = out.label.clutter
    assert len(clutter) == 6 and all(c["kind"] == "rock" for c in clutter)
    ids, heights = renderer64.camera_hits()  # the surface the render just saw, chip units
    heights = heights.reshape(64, 64) * scene.sonar.chip_size / 2  # m
    inside = np.zeros((64, 64), dtype=bool)
    for c in clutter:
        c0, r0, c1, r1 = c["bbox"]
        inside[r0:r1, c0:c1] = True
        col, row = c["pixel_centre"]
        assert c0 <= col < c1 and r0 <= row < r1
        # the box's centre pixel is on the rock: raised by most of its height
        assert heights[int(round(row)), int(round(col))] > 0.5 * c["radius_m"], c
    smallest = min(c["radius_m"] for c in clutter)
    raised = heights > 0.2 * smallest
    bright = out.image > 1.3 * np.median(out.image)
    assert raised.sum() > 20 and bright.sum() > 5
    assert inside[raised].all() and inside[bright].all()
    # written only when there is clutter, read back the same; a record without it reads as none
    record = out.label.to_json()
    assert ChipLabel.from_json(record).clutter == clutter
    record.pop("clutter")
    assert ChipLabel.from_json(record).clutter == () and "clutter" not in ChipLabel.from_json(record).to_json()


def test_workers_split_a_shard_among_them(tmp_path, capsys):
    """--workers 2 with --shard 1/2: two processes render scenes 1 and 5, and 3 (shards 1/4 and 3/4), no other."""
    from sasmi.cli.main import main

    args = ["render", str(REPO / "scenes" / "muscle_paper.toml"), "--count", "6", "--size", "32", "--spp", "2"]
    assert main([*args, "--out", str(tmp_path / "one"), "--shard", "1/2"]) == 0
    assert main([*args, "--out", str(tmp_path / "two"), "--shard", "1/2", "--workers", "2"]) == 0
    assert "3 chips of 6 chips are not complete yet" in capsys.readouterr().out
    for folder in ("images", "masks", "labels"):
        names = sorted(p.name for p in (tmp_path / "two" / folder).iterdir())
        assert [n[:6] for n in names] == ["000001", "000003", "000005"]
        assert all((tmp_path / "two" / folder / n).read_bytes() == (tmp_path / "one" / folder / n).read_bytes()
                   for n in names)
