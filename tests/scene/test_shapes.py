"""The target shapes are closed meshes of the asked size; the box, torus and boulder render with masks, labels and
burial that make sense, and the same image in Mitsuba and POV-Ray."""
from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest
import trimesh

from sasmi.labels import BUILTIN_CATEGORIES
from sasmi.render import crosscheck as xc
from sasmi.render import povray
from sasmi.render.geometry import _unit_shape, build_geometry
from sasmi.render.mitsuba import Renderer, render
from sasmi.scene.model import SIZE_FIELDS, Post, Scene, Seafloor, Sonar, Target, target_height

BOX = Target(shape="box", yaw=30.0, length=1.6, width=0.8, height=0.6)
TORUS = Target(shape="torus", radius=0.5, tube_radius=0.15)
BOULDER = Target(shape="boulder", yaw=20.0, length=1.6, width=1.2, height=0.8, lumpiness=0.6)
needs_povray = pytest.mark.skipif(shutil.which(povray.POVRAY) is None, reason="povray not installed (make setup)")


def scene_with(target: Target) -> Scene:
    """A 6 m chip at 20-26 m range, 5 m altitude, flat floor, no speckle: the target alone makes the contrast."""
    return Scene(sonar=Sonar(max_range=50.0, altitude=5.0, near_range=20.0, chip_size=6.0, track_length=4.0,
                             emitters=8, cone_angle=45.0),
                 seafloor=Seafloor(rms_height=0.0), targets=(target,), post=Post(gain=0.4), seed=1)


@pytest.mark.parametrize("target, extent", [
    (Target(shape="cylinder", radius=0.3, length=2.0), (2.0, 0.6, 0.6)),  # lying along x
    (Target(shape="sphere", radius=0.4), (0.8, 0.8, 0.8)),
    (Target(shape="cone", radius=0.5, radius_top=0.2, length=0.9), (1.0, 1.0, 0.9)),  # standing: length is its height
    (BOX, (1.6, 0.8, 0.6)),
    (TORUS, (1.3, 1.3, 0.3)),  # 2 (R + r) across, 2 r high
    (BOULDER, (1.6, 1.2, 0.8)),
])
def test_shapes_are_closed_meshes_of_the_asked_size(target, extent):
    v, f = _unit_shape(dataclasses.replace(target, yaw=0.0), "targets[0]")
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0  # outward faces: lit from outside
    np.testing.assert_allclose(v.max(0) - v.min(0), extent, atol=1e-6)
    assert v[:, 2].min() == 0.0  # stands on the floor


def test_a_cone_narrows_to_its_top_radius():
    v, _ = _unit_shape(Target(shape="cone", radius=0.5, radius_top=0.2, length=0.9), "targets[0]")
    radial = np.hypot(v[:, 0], v[:, 1])
    np.testing.assert_allclose([radial[v[:, 2] == 0].max(), radial[v[:, 2] == v[:, 2].max()].max()], [0.5, 0.2])


def test_torus_is_a_ring_lying_flat():
    """A tyre: every vertex on the tube around the ring in the floor's plane, the floor seen through the middle."""
    v, _ = _unit_shape(TORUS, "targets[0]")
    centre = v[:, 2].max() / 2
    tube = np.hypot(np.hypot(v[:, 0], v[:, 1]) - TORUS.radius, v[:, 2] - centre)
    np.testing.assert_allclose(tube, TORUS.tube_radius, rtol=1e-6)
    assert np.hypot(v[:, 0], v[:, 1]).min() >= TORUS.radius - TORUS.tube_radius - 1e-9  # the hole


def _radial_spread(target: Target) -> float:
    """Spread of the distance from the centre, on the boulder squashed back to a unit sphere: 0 for an ellipsoid."""
    v, _ = _unit_shape(target, "targets[0]")
    unit = (v - (v.max(0) + v.min(0)) / 2) / [target.length, target.width, target.height] * 2
    return float(np.linalg.norm(unit, axis=1).std())


def test_boulder_is_lumpy_and_keeps_its_shape_when_moved():
    """Lumpiness makes the surface stray from an ellipsoid; the lumps depend on the boulder's size and
    lumpiness alone, so a pose sweep or a differentiable render that moves it does not reshape it."""
    smooth = dataclasses.replace(BOULDER, lumpiness=0.0)
    assert _radial_spread(smooth) < 1e-6 < 0.05 < _radial_spread(BOULDER)
    assert _radial_spread(dataclasses.replace(BOULDER, lumpiness=0.3)) < _radial_spread(BOULDER)
    v, _ = _unit_shape(BOULDER, "targets[0]")
    moved, _ = _unit_shape(dataclasses.replace(BOULDER, x=-2.0, y=1.0, yaw=75.0, burial=0.2), "targets[0]")
    np.testing.assert_array_equal(v, moved)
    other, _ = _unit_shape(dataclasses.replace(BOULDER, length=1.7), "targets[0]")
    other_unit = other / [1.7, 1.2, 0.8]
    assert np.abs(other_unit - v / [1.6, 1.2, 0.8]).max() > 0.05  # another size, other lumps


@pytest.mark.parametrize("target", [BOX, TORUS, BOULDER], ids=["box", "torus", "boulder"])
def test_new_shapes_render_with_masks_labels_and_burial(target):
    size = 48
    out = render(scene_with(target), size=size, spp=4)
    label = out.label.targets[0]
    assert label.category == target.shape and target.shape in BUILTIN_CATEGORIES
    sizes = set().union(*SIZE_FIELDS.values())  # of the size fields, the label keeps its shape's alone
    assert {k for k in label.params if k in sizes} == set(SIZE_FIELDS[target.shape])
    assert label.visible_pixels > 10 and label.shadow_pixels > 10
    c0, r0, c1, r1 = label.bbox
    col, row = label.pixel_centre
    assert c0 <= col <= c1 and r0 <= row <= r1  # the mask lies where the label says the target is
    assert (out.mask == 1).sum() == label.visible_pixels and (out.instances == 1).sum() == label.visible_pixels
    # the shadow falls behind the target, away from the track (+x)
    rows, cols = np.nonzero(out.mask == 2)
    assert cols.mean() > col
    # a lit target is brighter than the floor, its shadow darker
    floor = np.median(out.image[out.mask == 0])
    assert out.image[out.mask == 1].max() > 1.5 * floor and out.image[out.mask == 2].mean() < 0.5 * floor
    # burying it deeper hides part of it and shortens its shadow
    deeper = render(scene_with(dataclasses.replace(target, burial=0.6 * target_height(target))),
                    size=size, spp=4).label.targets[0]
    assert deeper.shadow_pixels < 0.8 * label.shadow_pixels
    assert deeper.visible_pixels <= label.visible_pixels


@needs_povray
@pytest.mark.parametrize("target", [BOX, TORUS, BOULDER], ids=["box", "torus", "boulder"])
def test_new_shapes_agree_with_povray(target):
    scene = scene_with(target)
    size = 32
    renderer = Renderer(size=size, spp=64)
    pov, _ = xc.povray_side(scene, size)
    m = xc.compare(xc.mitsuba_side(scene, renderer), pov)
    assert m.passed, xc.table(m)
    # and the comparison sees the target: POV-Ray's mask pass puts it where Mitsuba does
    sdl = povray.geometry_sdl(build_geometry(scene, size))
    assert povray.target_mask(sdl, size).sum() > 5


@needs_povray
def test_rough_backscatter_agrees_with_povray():
    """A rough boulder (cos^0.5; POV-Ray: brilliance 0.5) renders alike in both, and the law is seen: its
    pixels shine about 1.5x as bright as a lambert boulder's, in both renderers."""
    size = 32
    renderer = Renderer(size=size, spp=64)
    rough = scene_with(dataclasses.replace(BOULDER, backscatter="rough"))
    mitsuba, (pov, _) = xc.mitsuba_side(rough, renderer), xc.povray_side(rough, size)
    m = xc.compare(mitsuba, pov)
    assert m.passed, xc.table(m)
    lambert = xc.mitsuba_side(scene_with(BOULDER), renderer)
    both = mitsuba.target & pov.target & lambert.target

    def target_level(side: xc.Side) -> float:
        return float(side.radiance[both].mean())

    assert target_level(mitsuba) == pytest.approx(target_level(pov), rel=0.05)
    assert target_level(mitsuba) > 1.3 * target_level(lambert)
