"""Companions: other objects in view beside a chip's target, placed clear of it, with their own labels."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from sasmi.errors import SasmiError
from sasmi.render.mitsuba import render
from sasmi.scene.preset import Preset

BASE = {
    "sonar": {"chip_size": 12.0, "near_range": 30.0},
    "targets_per_chip": 1,
    "targets": [{"shape": "cylinder", "x": {"uniform": [-1.0, 1.0]}, "y": {"normal": [0.0, 0.4]},
                 "yaw": {"uniform": [0.0, 180.0]}}],
}
COMPANIONS = {"share": 0.4, "most": 3, "clearance": 2.5,
              "kinds": [{"shape": "boulder", "weight": 3, "length": {"uniform": [0.6, 1.2]}, "width": 0.6,
                         "height": 0.4},
                        {"shape": "sphere", "weight": 1, "radius": 0.3}]}


def with_companions(**settings) -> Preset:
    raw = copy.deepcopy(BASE)
    raw["companions"] = {**copy.deepcopy(COMPANIONS), **settings}
    return Preset.from_dict(raw)


def test_companions_lie_clear_of_the_target_and_of_each_other():
    preset = with_companions()
    scenes = [preset.sample(0, i) for i in range(300)]
    counts = [len(s.targets) - 1 for s in scenes]
    assert 0.32 < np.mean([c > 0 for c in counts]) < 0.48  # share 0.4
    assert set(counts) == {0, 1, 2, 3}  # 1 to most
    half = 6.0 - 2.5 / 2
    for s in scenes:
        for i, c in enumerate(s.targets[1:], start=1):
            assert abs(c.x) <= half and abs(c.y) <= half
            assert all(math.hypot(c.x - o.x, c.y - o.y) >= 2.5 for o in s.targets[:i])
    shapes = [t.shape for s in scenes for t in s.targets[1:]]
    assert 0.65 < shapes.count("boulder") / len(shapes) < 0.85  # weight 3 : 1
    assert len({(t.x, t.y) for s in scenes for t in s.targets[1:]}) == len(shapes)  # placed anew each time
    assert preset.sample(0, 11) == scenes[11]  # a function of (seed, index) alone


def test_adding_companions_changes_no_other_draw():
    """Companions draw from their own stream: the chip's sonar, floor, target and speckle stay as they were,
    so a preset gains companions without redrawing its chips (and its measurements stay comparable)."""
    plain, busy = Preset.from_dict(copy.deepcopy(BASE)), with_companions(share=1.0)
    for i in range(20):
        before, after = plain.sample(0, i), busy.sample(0, i)
        assert len(after.targets) > 1
        assert after.targets[0] == before.targets[0] and after.seed == before.seed
        assert (after.sonar, after.seafloor, after.post) == (before.sonar, before.seafloor, before.post)


def test_companions_render_with_their_own_masks_and_labels():
    scene = with_companions(share=1.0, most=1).sample(0, 3)
    out = render(scene, size=48, spp=4)
    labels = out.label.targets
    assert [t.category for t in labels] == [t.shape for t in scene.targets] and len(labels) == 2
    assert all(t.visible_pixels > 0 for t in labels)
    assert {int(v) for v in np.unique(out.instances)} >= {1, 2}  # each object its own instance
    assert [t.role for t in labels] == ["target", "companion"] and out.label.to_json()["targets"][1]["role"] == "companion"


def test_exports_tell_companions_from_the_target_and_can_leave_them_out(tmp_path):
    """An ATR model learns contacts: a companion boulder is clutter, though labelled by its shape."""
    import json

    from sasmi.atr.datasets import RenderSet
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.atr.export import export_coco, export_yolo

    renders = render_set(RenderJob(preset=with_companions(share=1.0, most=2), out=tmp_path / "set", count=3,
                                   size=32, spp=2), progress=False)
    chips = RenderSet(renders)
    flags = [chips[i][1]["companion"].tolist() for i in range(len(chips))]
    assert all(f[0] is False and len(f) > 1 and all(f[1:]) for f in flags)  # the target first, then 1-2 companions
    coco = json.loads(export_coco(renders, tmp_path / "all.json").read_text())
    assert [a["role"] for a in coco["annotations"]] == ["companion" if c else "target" for f in flags for c in f]
    only = json.loads(export_coco(renders, tmp_path / "targets.json", companions=False).read_text())
    assert [a["role"] for a in only["annotations"]] == ["target"] * 3
    assert [a["bbox"] for a in only["annotations"]] == [a["bbox"] for a in coco["annotations"] if a["role"] == "target"]
    lines = [len(p.read_text().splitlines()) for p in sorted(export_yolo(renders, tmp_path / "y", companions=False).rglob("*.txt"))]
    assert lines == [1, 1, 1]


@pytest.mark.parametrize("settings, message", [
    ({"share": 1.5}, "companions.share: 1.5 is not allowed (allowed: in [0, 1])"),
    ({"most": 0}, "companions.most: 0 is not allowed (allowed: in [1, 16])"),
    ({"spread": 2}, "companions.spread: unknown key"),
    ({"clearance": 12.0}, "companions.clearance: 12 m leaves no room on a 12 m chip"),
    ({"kinds": []}, "companions.kinds: expected at least one [[companions.kinds]] table"),
    ({"kinds": [{"shape": "sphere", "x": 1.0}]}, "companions.kinds[0].x: companions are placed at random"),
    ({"kinds": [{"shape": "sphere", "role": "target"}]}, "companions.kinds[0].role: every companion has the role"),
    ({"kinds": [{"shape": "sphere", "weight": 0}]}, "companions.kinds: every weight is 0"),
    ({"kinds": [{"shape": "sphere", "radius": -1}]}, "companions.kinds[0].radius: -1.0 is not allowed"),
    ({"kinds": [{"shape": "box", "height": 0.3, "burial": 0.5}]}, "companions.kinds[0].burial: 0.5 m buries"),
])
def test_bad_companions_name_the_field(settings, message):
    with pytest.raises(SasmiError) as e:
        with_companions(**settings)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)
