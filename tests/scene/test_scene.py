"""Presets: validation errors name the field; sampling depends only on (seed, index)."""
from __future__ import annotations

import textwrap

import numpy as np
import pytest

from sasmi.cli.main import main
from sasmi.errors import SasmiError
from sasmi.scene.preset import Preset, load_preset

from conftest import REPO

BASE = """
[sonar]
chip_size = 6.0
[[targets]]
shape = "cylinder"
"""


def write(tmp_path, text: str):
    path = tmp_path / "p.toml"
    path.write_text(textwrap.dedent(text))
    return path


@pytest.mark.parametrize("text, field", [
    ("[sonar]\nfoo = 1\n", "sonar.foo: unknown key"),
    ("[sonr]\n", "sonr: unknown section"),
    ('[sonar]\nemitters = "many"\n', "sonar.emitters: expected int"),
    ("[sonar]\nchip_size = 0\n", "sonar.chip_size: 0.0 is not allowed (allowed: > 0)"),
    ("[sonar]\nmax_range = -5\n", "sonar.max_range"),
    ("[sonar]\nemitters = 0\n", "sonar.emitters: 0 is not allowed"),
    ("[[targets]]\nx = 4.0\n", "targets[0].x: 4 m lies outside the chip"),
    ("[[targets]]\nradius = 0.3\nburial = 0.7\n", "targets[0].burial"),
    ("[[targets]]\nburial = {uniform = [0.0, 0.9]}\nradius = 0.3\n", None),  # only some draws are too deep
    ("[seafloor]\nalbedo = {uniform = [0.5, 0.2]}\n", "seafloor.albedo.uniform: lower bound"),
    ("[seafloor]\nalbedo = {gauss = [0.5, 0.2]}\n", "seafloor.albedo: a distribution is one of"),
    ("[seafloor]\nalbedo = 1.5\n", "seafloor.albedo: 1.5 is not allowed (allowed: in [0, 1])"),
    ("[seafloor]\npatchiness = 5\n", "seafloor.patchiness: 5.0 is not allowed (allowed: in [0, 2])"),
    ('[[targets]]\nshape = "donut"\n', "targets[0].shape: 'donut' is not allowed"),
    ('[[targets]]\nshape = "torus"\nradius = 0.2\ntube_radius = 0.2\n', "targets[0].tube_radius: 0.2 m closes the ring"),
    ('[[targets]]\nshape = "box"\nheight = 0.4\nburial = 0.4\n', "targets[0].burial: 0.4 m buries the whole target"),
    ('[[targets]]\nshape = "boulder"\nheight = 0.4\nburial = 0.5\n', "targets[0].burial: 0.5 m buries the whole target"),
    ('[[targets]]\nshape = "boulder"\nlumpiness = 1.0\n', "targets[0].lumpiness: 1.0 is not allowed (allowed: in [0, 0.9))"),
    ('[[targets]]\nbackscatter = "shiny"\n', "targets[0].backscatter: 'shiny' is not allowed (allowed: one of lambert, lambert2, rough)"),
    # target kinds
    ('targets_per_chip = 1\n', "targets_per_chip: no [[targets]] tables to draw targets from"),
    ('targets_per_chip = -1\n[[targets]]\n', "targets_per_chip: -1 is not allowed (allowed: >= 0)"),
    ('targets_per_chip = "two"\n[[targets]]\n', "targets_per_chip: expected int"),
    ('targets_per_chip = 1\n[[targets]]\nweight = -2\n', "targets[0].weight: -2.0 is not allowed (allowed: >= 0)"),
    ('targets_per_chip = 1\n[[targets]]\nweight = {uniform = [0, 1]}\n', "targets[0].weight: a number, not a distribution"),
    ('targets_per_chip = 1\n[[targets]]\nweight = 0\n[[targets]]\nweight = 0\n', "targets: every weight is 0"),
    ('[[targets]]\nweight = 2\n', "targets[0].weight: only used with a top-level targets_per_chip"),
    ('targets_per_chip = 1\n[[targets]]\nwieght = 2\n', "targets[0].wieght: unknown key"),
    # a kind that one chip's draw may not pick is still checked at load
    ('targets_per_chip = 1\n[[targets]]\nweight = 1000\n[[targets]]\nweight = 0.001\nshape = "sphere"\nradius = 0.5\n'
     'burial = 1.5\n', "targets[1].burial: 1.5 m buries the whole target"),
    ('[[targets]]\nshape = "mesh"\n', "targets[0].mesh: a file path is required"),
    # seafloor kinds
    ('[[seafloor]]\nweight = -1\n', "seafloor[0].weight: -1.0 is not allowed (allowed: >= 0)"),
    ('[[seafloor]]\nweight = 0\n[[seafloor]]\nweight = 0\n', "seafloor: every weight is 0"),
    ('[[seafloor]]\n[[seafloor]]\nalbdeo = 0.5\n', "seafloor[1].albdeo: unknown key"),
    ('[seafloor]\nweight = 2\n', "seafloor.weight: unknown key"),
    ('seafloor = 3\n', "seafloor: expected a table ([seafloor]) or at least one [[seafloor]] table"),
    # a kind that one chip's draw may not pick is still checked at load
    ('[sonar]\naltitude = 1.0\n[[seafloor]]\nweight = 1000\n[[seafloor]]\nweight = 0.001\nrms_height = 0.2\n'
     'ripple_amplitude = 0.4\n', "seafloor[1]: relief up to 1.2 m"),
    ("[sonar]\nnear_range = 58.0\n", "sonar.near_range: chip far edge"),
])
def test_bad_preset_names_the_field(tmp_path, text, field):
    path = write(tmp_path, text)
    if field is None:  # a distribution reaching an invalid value fails on the draw that reaches it
        preset = Preset.from_dict({"targets": [{"burial": {"uniform": [0.0, 0.9]}, "radius": 0.3}]})
        with pytest.raises(SasmiError, match=r"targets\[0\].burial"):
            for i in range(50):
                preset.sample(0, i)
        return
    with pytest.raises(SasmiError) as e:
        load_preset(path)
    assert field in str(e.value)
    assert "\n" not in str(e.value)


def test_missing_and_broken_preset(tmp_path):
    with pytest.raises(SasmiError, match="preset not found"):
        load_preset(tmp_path / "nope.toml")
    with pytest.raises(SasmiError, match="not valid TOML"):
        load_preset(write(tmp_path, "[sonar\n"))


def test_sampling_depends_only_on_seed_and_index():
    preset = load_preset(REPO / "scenes" / "muscle_paper.toml")
    a = [preset.sample(3, i) for i in range(5)]
    assert preset.sample(3, 4) == a[4]  # scene 4 alone equals scene 4 after 0..3
    assert len({s.targets[0].yaw for s in a}) == 5  # distributions really vary
    assert preset.sample(4, 0) != a[0]
    for s in a:
        assert 30.0 <= s.sonar.near_range <= 50.0
        assert 0.0 <= s.targets[0].burial <= 0.25


def test_normal_over_an_integer_field_and_a_bounded_field_loads():
    """Bounds on a normal's mean and std stop only draws that could never be in range."""
    preset = Preset.from_dict({"sonar": {"emitters": {"normal": [32.5, 2.0]}, "chip_size": {"normal": [6.0, 0.05]}}})
    assert all(isinstance(preset.sample(0, i).sonar.emitters, int) for i in range(5))


def test_choice_and_integer_uniform():
    preset = Preset.from_dict({"seafloor": {"rocks": {"uniform": [0, 4]}},
                               "targets": [{"shape": {"choice": ["sphere", "cone"]}}]})
    scenes = [preset.sample(0, i) for i in range(40)]
    assert {s.targets[0].shape for s in scenes} == {"sphere", "cone"}
    assert all(isinstance(s.seafloor.rocks, int) and 0 <= s.seafloor.rocks <= 4 for s in scenes)


def test_target_grid_covers_the_field():
    scene = load_preset(REPO / "scenes" / "target_field.toml").sample(0, 0)
    assert len(scene.targets) == 144
    xs = sorted({round(t.x) for t in scene.targets})
    assert xs[0] < -25 and xs[-1] > 25
    assert len({t.yaw for t in scene.targets}) == 144


@pytest.mark.parametrize("args, message", [
    (["--size", "40"], "argument --size: 40 is not a multiple of 16"),
    (["--size", "0"], "argument --size: 0 is out of range (allowed: a multiple of 16, 16 to 4096"),
    (["--count", "0"], "argument --count: 0 is out of range"),
    (["--spp", "-1"], "argument --spp: -1 is out of range"),
])
def test_cli_bad_flags_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    code = main(["render", str(REPO / "scenes" / "cylinder_chip.toml"), "--out", str(out), *args])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_cli_bad_preset_exit_2_and_write_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    bad = write(tmp_path, "[[targets]]\nradius = 0.3\nburial = 0.6\n")
    assert main(["render", str(bad), "--out", str(out), "--size", "32"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sasmi render: error: targets[0].burial") and len(err.splitlines()) == 1
    assert not out.exists()
    assert main(["render", str(tmp_path / "missing.toml"), "--out", str(out)]) == 2
    assert "missing.toml: preset not found" in capsys.readouterr().err
    assert not out.exists()


def test_cli_missing_mesh_exit_2(tmp_path, capsys):
    preset = write(tmp_path, '[[targets]]\nshape = "mesh"\nmesh = "nothere.obj"\n')
    out = tmp_path / "out"
    assert main(["render", str(preset), "--out", str(out), "--size", "32", "--count", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "targets[0].mesh" in err and "nothere.obj" in err and len(err.splitlines()) == 1
    assert not (out / "images").exists()


def test_mesh_kinds_are_found_beside_the_preset_from_any_folder(tmp_path, monkeypatch):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=[1.0, 0.6, 0.5]).export(tmp_path / "meshes" / "drum.obj")
    preset = write(tmp_path, 'targets_per_chip = 1\n[[targets]]\nshape = "mesh"\nmesh = "meshes/drum.obj"\n'
                             '[[targets]]\nshape = "sphere"\n')
    monkeypatch.chdir(tmp_path.parent)  # not the preset's folder: its relative mesh path must still resolve
    meshes = {t.mesh for i in range(20) for t in load_preset(preset).sample(0, i).targets if t.shape == "mesh"}
    assert meshes == {str(tmp_path / "meshes" / "drum.obj")}


def test_target_kinds_are_drawn_by_weight():
    preset = Preset.from_dict({
        "targets_per_chip": {"choice": [1, 2]},
        "targets": [{"shape": "box", "weight": 3, "length": {"uniform": [1.0, 2.0]}},
                    {"shape": "torus", "weight": 1, "radius": 0.4, "tube_radius": 0.1},
                    {"shape": "sphere", "weight": 0}]})
    scenes = [preset.sample(0, i) for i in range(300)]
    counts = [len(s.targets) for s in scenes]
    assert set(counts) == {1, 2} and 0.4 < counts.count(1) / len(counts) < 0.6
    shapes = [t.shape for s in scenes for t in s.targets]
    assert "sphere" not in shapes  # weight 0: never drawn
    assert 0.68 < shapes.count("box") / len(shapes) < 0.82  # 3 : 1
    boxes = [t for s in scenes for t in s.targets if t.shape == "box"]
    assert all(1.0 <= t.length <= 2.0 for t in boxes) and len({t.length for t in boxes}) == len(boxes)
    assert all(t.radius == 0.4 and t.tube_radius == 0.1 for s in scenes for t in s.targets if t.shape == "torus")
    assert preset.sample(0, 7) == scenes[7]  # still a function of (seed, index) alone


def test_seafloor_kinds_are_drawn_by_weight_and_one_table_draws_as_before():
    kinds = [{"weight": 3, "name": "waves", "ripple_amplitude": {"uniform": [0.05, 0.1]}},
             {"weight": 1, "mosaic_contrast": 0.4, "albedo": 0.3}, {"weight": 0, "rocks": 8}]
    preset = Preset.from_dict({"seafloor": kinds})
    floors = [preset.sample(0, i).seafloor for i in range(400)]
    waves = [f for f in floors if f.ripple_amplitude > 0]
    assert 0.68 < len(waves) / len(floors) < 0.82  # 3 : 1
    assert all(f.mosaic_contrast == 1 and f.albedo == 0.5 and f.name == "waves" for f in waves)  # the rest default
    assert all(f.mosaic_contrast == 0.4 and f.albedo == 0.3 and f.name == "" for f in floors if f.ripple_amplitude == 0)
    assert not any(f.rocks for f in floors)  # weight 0: never drawn
    assert len({f.ripple_amplitude for f in waves}) == len(waves)  # drawn per chip within the kind
    assert preset.sample(0, 7).seafloor == floors[7]
    # one [seafloor] table draws nothing more: every other draw of its scenes is as without kinds
    one = {"seafloor": {"ripple_amplitude": {"uniform": [0.05, 0.1]}}, "post": {"gain": {"uniform": [0.3, 0.6]}}}
    rng = np.random.default_rng([0, 3])  # the draws in field order: the ripples' amplitude, then the gain
    amplitude, gain = rng.uniform(0.05, 0.1), rng.uniform(0.3, 0.6)
    scene = Preset.from_dict(one).sample(0, 3)
    assert (scene.seafloor.ripple_amplitude, scene.post.gain) == (amplitude, gain)


def test_a_kinds_bad_draw_names_its_table():
    """A drawn target that breaks a cross-field check names the [[targets]] table it came from."""
    with pytest.raises(SasmiError, match=r"^targets\[1\]\.x: .* lies outside the chip"):
        preset = Preset.from_dict({"targets_per_chip": 1, "sonar": {"chip_size": 6.0},
                                   "targets": [{"shape": "sphere", "weight": 1},
                                               {"shape": "cone", "weight": 1, "x": {"uniform": [0.0, 6.0]}}]})
        for i in range(200):
            preset.sample(0, i)


def test_shipped_default_preset_draws_every_kind():
    preset = load_preset("cylinder_chip")
    shapes = {s.targets[0].shape for s in (preset.sample(0, i) for i in range(200))}
    assert shapes == {"cylinder", "sphere", "box", "torus", "cone", "boulder"}


def test_cli_bad_target_kind_exit_2(tmp_path, capsys):
    bad = write(tmp_path, "targets_per_chip = 1\n[[targets]]\nweight = -1\n")
    out = tmp_path / "out"
    assert main(["render", str(bad), "--out", str(out), "--size", "32"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sasmi render: error: targets[0].weight") and len(err.splitlines()) == 1
    assert not out.exists()
