"""Bad input never crashes: each case goes through the CLI's entry point and must exit 2 with at
most 3 lines on stderr naming the flag, field or file, no traceback, and nothing left in the output folder.

Most cases run in-process (`sasmi.cli.main.main`); a sample runs as `python -m sasmi` so start-up is covered too.
Sizes are tiny and every case fails before a renderer or a network starts.
"""
from __future__ import annotations

import dataclasses
import errno
import json
import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sasmi.cli.main import main
from sasmi.images import write_gray
from sasmi.scene.model import Post, Seafloor, Sonar, Target

from conftest import REPO

CYLINDER = REPO / "scenes" / "cylinder_chip.toml"
TINY = ["--count", "1", "--size", "16", "--spp", "1"]


# ------------------------------------------------------------------------------------------ fixtures

@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Folders and files shared by the cases: chips, empty and useless folders, broken run folders."""
    root = tmp_path_factory.mktemp("inputs")
    rng = np.random.default_rng(0)
    chips = root / "chips"
    for i in range(4):
        write_gray(chips / f"{i}.png", rng.random((32, 32)))
    (root / "empty").mkdir()
    junk = root / "junk"  # two files that only look like images
    junk.mkdir()
    (junk / "a.png").write_text("not an image")
    (junk / "b.npy").write_bytes(b"\x93NUMPY garbage")
    texts = root / "texts"
    texts.mkdir()
    (texts / "notes.txt").write_text("no images here")
    (root / "a_file").write_text("a file where a folder belongs")
    for name, raw in _checkpoint_bytes().items():
        for kind in ("autoencoder", "sasgan"):
            _run_folder(root / f"{kind}_{name}", kind, raw)
    _run_folder(root / "dcgan_run", "dcgan", b"")  # a run of another kind
    no_ckpt = root / "sasgan_no_checkpoint"
    no_ckpt.mkdir()
    (no_ckpt / "config.json").write_text(json.dumps({"kind": "sasgan", "config": {"size": 32}}))
    bad_config = root / "sasgan_bad_config"
    bad_config.mkdir()
    (bad_config / "config.json").write_text("{ not json")
    return {"root": root, "chips": chips, "empty": root / "empty", "junk": junk, "texts": texts,
            "file": root / "a_file"}


class _Code:
    """Pickles as a call to os.system: a checkpoint carrying code."""

    def __reduce__(self):
        return os.system, ("echo pwned",)


def _checkpoint_bytes() -> dict[str, bytes]:
    import io

    import torch

    good = io.BytesIO()
    torch.save({"step": 1, "best": 0.0, "torch_rng": torch.get_rng_state(),
                "state": {"generator": {"w": torch.zeros(2)}, "autoencoder": {"w": torch.zeros(2)}}}, good)
    code = io.BytesIO()
    torch.save({"state": _Code()}, code)
    return {
        "empty": b"",
        "truncated": good.getvalue()[: len(good.getvalue()) // 2],
        "random": np.random.default_rng(1).bytes(4096),
        "pickle_code": pickle.dumps(_Code()),
        "torch_code": code.getvalue(),
        "other_net": good.getvalue(),  # loads, but its weights fit no sasmi network
        "not_dict": pickle.dumps([1, 2, 3]),
        "torch_list": _torch_bytes([1, 2, 3]),  # loads, but is not a checkpoint
        "torch_no_state": _torch_bytes({"step": 1}),  # loads, lacks the weights
    }


def _torch_bytes(obj) -> bytes:
    import io

    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _run_folder(path: Path, kind: str, checkpoint: bytes) -> None:
    (path / "checkpoints").mkdir(parents=True)
    (path / "config.json").write_text(json.dumps({"kind": kind, "config": {"size": 32}}))
    for which in ("last", "best"):
        (path / "checkpoints" / f"{which}.pt").write_bytes(checkpoint)


def preset(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "preset.toml"
    path.write_text(textwrap.dedent(text))
    return path


def assert_refused(code: int, err: str, names: tuple[str, ...], out: Path | None) -> None:
    lines = err.strip().splitlines()
    assert code == 2, f"exit {code}: {err}"
    assert "Traceback" not in err, err
    assert 1 <= len(lines) <= 3, err
    assert lines[-1].startswith("sasmi") and ": error: " in lines[-1], err
    assert any(name in err for name in names), f"none of {names} in: {err}"
    if out is not None:
        assert not out.exists() or out.is_file() or not any(out.iterdir()), f"left behind: {list(out.rglob('*'))}"


def refused(capsys, argv: list[str], names: str | tuple[str, ...], out: Path | None) -> None:
    code = main([str(a) for a in argv])
    assert_refused(code, capsys.readouterr().err, (names,) if isinstance(names, str) else names, out)


# ------------------------------------------------------------------------------------------ presets

def _fields(cls) -> list[str]:
    return [f.name for f in dataclasses.fields(cls) if type(f.default) in (int, float) and type(f.default) is not bool]


SECTIONS = {"sonar": Sonar, "seafloor": Seafloor, "post": Post}
NON_FINITE = []  # every number in every section, so a field added later is covered too
for _section, _cls in SECTIONS.items():
    for _name in _fields(_cls):
        for _value in ("nan", "inf"):
            NON_FINITE.append((f"[{_section}]\n{_name} = {_value}\n", f"{_section}.{_name}"))
for _name in _fields(Target):
    for _value in ("nan", "inf", "-inf"):
        NON_FINITE.append((f"[[targets]]\n{_name} = {_value}\n", f"targets[0].{_name}"))

PRESETS = NON_FINITE + [
    # huge
    ("[sonar]\nemitters = 10000000\n", "sonar.emitters"),
    ("[seafloor]\nrocks = 10000000\n", "seafloor.rocks"),
    ("[sonar]\nmax_range = 1e300\n", "sonar.max_range"),
    ("[sonar]\nchip_size = 1e9\nmax_range = 2e9\n", "sonar.chip_size"),
    ("[sonar]\nmax_range = 100000000000000000000000000000000000000000\n", "sonar.max_range"),
    ("[[targets]]\nlength = 1e6\n", "targets[0].length"),
    ("[post]\ngain = 1e308\n", "post.gain"),
    ("[sonar]\nintensity = 1e9\n", "sonar.intensity"),
    ("[seafloor]\nrocks = {uniform = [0, 1000000000]}\n", "seafloor.rocks"),
    ("[[targets]]\nyaw = 1e20\n", "targets[0].yaw"),
    # negative and zero
    ("[sonar]\nemitters = -1\n", "sonar.emitters"),
    ("[seafloor]\nrocks = -5\n", "seafloor.rocks"),
    ("[sonar]\nchip_size = -1.0\n", "sonar.chip_size"),
    ("[sonar]\ncone_angle = 0\n", "sonar.cone_angle"),
    ("[[targets]]\nradius = -0.3\n", "targets[0].radius"),
    ("[post]\nnoise_std = -1\n", "post.noise_std"),
    ("[seafloor]\nalbedo = -0.1\n", "seafloor.albedo"),
    # wrong types
    ('[sonar]\nemitters = "many"\n', "sonar.emitters"),
    ("[sonar]\nemitters = 3.5\n", "sonar.emitters"),
    ("[sonar]\nemitters = true\n", "sonar.emitters"),
    ("[post]\ntvg = 1\n", "post.tvg"),
    ("[[targets]]\nshape = 3\n", "targets[0].shape"),
    ('[seafloor]\nalbedo = "x"\n', "seafloor.albedo"),
    ("sonar = 5\n", "sonar"),
    ("targets = 5\n", "targets"),
    ("targets = [1, 2]\n", "targets[0]"),
    ("[sonar]\nmax_range = [1, 2]\n", "sonar.max_range"),
    ("[sonar]\nmax_range = 1979-05-27\n", "sonar.max_range"),
    ("description = 5\n", "description"),
    ('[[targets]]\nshape = "donut"\n', "targets[0].shape"),
    # distributions
    ("[seafloor]\nalbedo = {uniform = [nan, 0.5]}\n", "seafloor.albedo"),
    ("[seafloor]\nalbedo = {normal = [0.5, inf]}\n", "seafloor.albedo"),
    ("[seafloor]\nalbedo = {normal = [0.5, -1]}\n", "seafloor.albedo"),
    ("[seafloor]\nalbedo = {normal = [nan, 0.1]}\n", "seafloor.albedo"),
    ("[seafloor]\nalbedo = {uniform = [0.5]}\n", "seafloor.albedo"),
    ('[seafloor]\nalbedo = {uniform = "a"}\n', "seafloor.albedo"),
    ("[seafloor]\nalbedo = {choice = []}\n", "seafloor.albedo"),
    ("[seafloor]\nalbedo = {uniform = [0.1, 0.2], normal = [0.1, 0.1]}\n", "seafloor.albedo"),
    ("[[targets]]\nyaw = {choice = [0.0, nan]}\n", "targets[0].yaw"),
    ("[sonar]\nemitters = {normal = [32, 1e12]}\n", "sonar.emitters"),
    ("[[targets]]\nyaw = {normal = [0, 1e6]}\n", "targets[0].yaw"),
    ("[[targets]]\nyaw = {normal = [1e6, 1]}\n", "targets[0].yaw"),
    # unknown keys
    ("[sonar]\nfoo = 1\n", "sonar.foo"),
    ("[sonr]\n", "sonr"),
    ("colour = 'red'\n", "colour"),
    ("[[targets]]\ncolour = 'red'\n", "targets[0].colour"),
    ("[target_grid]\nfoo = 1\n", "target_grid.foo"),
    # target_grid
    ("target_grid = 5\n", "target_grid"),
    ("target_grid = [1, 2]\n", "target_grid"),
    ('target_grid = "x"\n', "target_grid"),
    ("[sonar]\nchip_size = 60.0\nmax_range = 100.0\n[target_grid]\nspacing = 0.001\n", "target_grid.spacing"),
    ("[sonar]\nchip_size = 60.0\nmax_range = 100.0\n[target_grid]\nspacing = 0.5\n", "target_grid.spacing"),
    ("[target_grid]\nspacing = nan\n", "target_grid.spacing"),
    ('[target_grid]\nspacing = "5"\n', "target_grid.spacing"),
    ("[target_grid]\njitter = inf\n", "target_grid.jitter"),
    ("[target_grid]\ntarget = 5\n", "target_grid.target"),
    ("[target_grid]\ntarget = [1]\n", "target_grid.target"),
    ("[target_grid.target]\nx = 1.0\n", "target_grid.target.x"),
    ("[target_grid.target]\nyaw = nan\n", "target_grid.target.yaw"),
    ("[target_grid]\nspacing = 10.0\n", "target_grid.spacing"),  # larger than the 6 m chip
    # cross-field and meshes
    ("[sonar]\nnear_range = 58.0\n", "sonar.near_range"),
    ("[[targets]]\nradius = 0.3\nburial = 0.7\n", "targets[0].burial"),
    ('[[targets]]\nshape = "mesh"\n', "targets[0].mesh"),
    ('[[targets]]\nshape = "mesh"\nmesh = "nothere.obj"\n', "nothere.obj"),
    ('[[targets]]\nshape = "mesh"\nmesh = "/dev/zero"\n', "/dev/zero"),
    ('[[targets]]\nshape = "mesh"\nmesh = "/tmp"\n', "targets[0].mesh"),
    ("[[targets]]\nx = 1e400\n", "targets[0].x"),
    ("[seafloor]\nrocks = 1000\nrock_radius = 100.0\n", "seafloor"),  # rocks above the array: a black chip
    ("[[targets]]\nlength = 100.0\nradius = 100.0\nburial = 99.0\n", "targets[0]"),  # a tower into the array
    ("[post]\ngain = 1e-300\n", "post.gain"),  # a black chip
    ("[sonar]\nintensity = 1000.0\n", "sonar.intensity"),  # a white chip
    ('[[targets]]\nshape = "mesh"\nmesh = "a\\u0000b.obj"\n', "targets[0].mesh"),
    ("[[targets]]\n" * 1025, "targets"),
]


@pytest.mark.parametrize("text, field", PRESETS, ids=[f"preset-{i}" for i in range(len(PRESETS))])
def test_bad_preset(tmp_path, capsys, text, field):
    out = tmp_path / "out"
    refused(capsys, ["render", preset(tmp_path, text), "--out", out, *TINY], field, out)


def _garbage_mesh(tmp_path):
    (tmp_path / "junk.obj").write_bytes(np.random.default_rng(0).bytes(2000))
    return '[[targets]]\nshape = "mesh"\nmesh = "junk.obj"\n'


PRESET_FILES = {
    "dev-zero": lambda tmp: Path("/dev/zero"),
    "folder": lambda tmp: tmp,
    "missing": lambda tmp: tmp / "missing.toml",
    "huge": lambda tmp: preset(tmp, "# padding\n" * 200_000),
    "binary": lambda tmp: (tmp / "b.toml", (tmp / "b.toml").write_bytes(b"\xff\xfe\x00 binary"))[0],
    "not-toml": lambda tmp: preset(tmp, "[sonar\n"),
    "fifo": lambda tmp: (tmp / "fifo.toml", os.mkfifo(tmp / "fifo.toml"))[0],
    "symlink-dev-zero": lambda tmp: (tmp / "z.toml", os.symlink("/dev/zero", tmp / "z.toml"))[0],
    "deep-nesting": lambda tmp: preset(tmp, "x = " + "[" * 5000 + "]" * 5000 + "\n"),
    "garbage-mesh": lambda tmp: preset(tmp, _garbage_mesh(tmp)),
    "unknown-name": lambda tmp: Path("no_such_preset"),
}


@pytest.mark.parametrize("name", PRESET_FILES)
def test_bad_preset_file(tmp_path, capsys, name):
    path = PRESET_FILES[name](tmp_path)
    out = tmp_path / "out"
    names = (str(path), path.name, "targets[0].mesh")
    refused(capsys, ["render", path, "--out", out, *TINY], names, out)


def test_preset_by_name_is_found():
    from sasmi.scene.preset import load_preset

    assert load_preset("cylinder_chip").raw == load_preset(CYLINDER).raw


# ------------------------------------------------------------------------------------------ render flags

RENDER_FLAGS = [
    (["--seed", "-1"], "--seed"),
    (["--seed", str(2**64)], "--seed"),
    (["--seed", "abc"], "--seed"),
    (["--seed", "1.5"], "--seed"),
    (["--count", "0"], "--count"),
    (["--count", "-3"], "--count"),
    (["--count", "1000000000"], "--count"),
    (["--count", "nan"], "--count"),
    (["--spp", "0"], "--spp"),
    (["--spp", "1000000000"], "--spp"),
    (["--size", "17"], "--size"),
    (["--size", "0"], "--size"),
    (["--size", "-16"], "--size"),
    (["--size", "1000000000"], "--size"),
    (["--size", "4096", "--spp", "4096"], "--size and --spp"),
    (["--workers", "0"], "--workers"),
    (["--workers", "-1"], "--workers"),
    (["--workers", "100000"], "--workers"),
    (["--format", "bad"], "--format"),
    (["--format", ""], "--format"),
]


@pytest.mark.parametrize("flags, name", RENDER_FLAGS, ids=[" ".join(f) for f, _ in RENDER_FLAGS])
def test_bad_render_flag(tmp_path, capsys, flags, name):
    out = tmp_path / "out"
    refused(capsys, ["render", CYLINDER, "--out", out, "--count", "1", "--size", "16", "--spp", "1", *flags],
            name, out)


@pytest.mark.parametrize("flags, name", [
    (["--seed", "-1"], "--seed"), (["--count", "0"], "--count"), (["--size", "17"], "--size"),
    (["--batch", "0"], "--batch"), (["--spp", "0"], "--spp"), (["--workers", "0"], "--workers"),
])
def test_bad_generate_flag(tmp_path, capsys, inputs, flags, name):
    out = tmp_path / "out"
    refused(capsys, ["generate", CYLINDER, "--generator", inputs["root"] / "sasgan_empty", "--out", out,
                     *TINY, *flags], name, out)


def test_a_bad_late_scene_fails_before_the_first_chip(tmp_path, capsys):
    """Only some draws bury the target whole: every scene is drawn before anything is written."""
    bad = preset(tmp_path, "[[targets]]\nradius = 0.3\nburial = {uniform = [0.0, 0.9]}\n")
    out = tmp_path / "out"
    refused(capsys, ["render", bad, "--out", out, "--count", "50", "--size", "16", "--spp", "1"], "burial", out)


def test_render_into_a_foreign_folder(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    refused(capsys, ["render", CYLINDER, "--out", out, *TINY], str(out), None)
    assert [p.name for p in out.iterdir()] == ["mine.txt"]


def test_render_out_is_a_file(tmp_path, capsys, inputs):
    out = tmp_path / "out"
    out.write_text("keep me")
    refused(capsys, ["render", CYLINDER, "--out", out, *TINY], str(out), None)
    assert out.read_text() == "keep me"


@pytest.mark.parametrize("where", ["under-a-file", "under-proc", "empty"])
def test_render_out_cannot_be_created(tmp_path, capsys, inputs, where):
    out = {"under-a-file": inputs["file"] / "out", "under-proc": Path("/proc/sasmi-test/out"), "empty": ""}[where]
    refused(capsys, ["render", CYLINDER, "--out", out, *TINY], ("--out", "/proc/sasmi-test"), None)
    assert not Path("/proc/sasmi-test").exists()


def test_full_disk_is_one_line(tmp_path, capsys, inputs, monkeypatch):
    def no_space(self, fp, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(fp))

    monkeypatch.setattr(Image.Image, "save", no_space)
    out = tmp_path / "sheet.png"
    refused(capsys, ["sheet", inputs["chips"], "--out", out], "No space left", tmp_path / "none")
    assert not out.exists() and not list(tmp_path.glob(".sheet*"))


def test_permission_error_is_one_line(tmp_path, capsys, inputs, monkeypatch):
    import sasmi.images

    def denied(path):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))

    monkeypatch.setattr(sasmi.images.Path, "mkdir", lambda self, *a, **k: denied(self))
    refused(capsys, ["sheet", inputs["chips"], "--out", tmp_path / "sub" / "sheet.png"], "Permission denied", None)


# ------------------------------------------------------------------------------------------ crosscheck, fit

@pytest.mark.parametrize("flags, name", [
    (["--index", "-1"], "--index"), (["--size", "17"], "--size"), (["--seed", "-1"], "--seed"),
    (["--size", "1000000000"], "--size"), (["--index", "x"], "--index"),
])
def test_bad_crosscheck_flag(tmp_path, capsys, flags, name):
    out = tmp_path / "out"
    refused(capsys, ["crosscheck", CYLINDER, "--out", out, "--size", "16", *flags], name, out)


@pytest.mark.parametrize("flags, name", [
    (["--steps", "0"], "--steps"), (["--lr", "nan"], "--lr"), (["--lr", "-1"], "--lr"), (["--spp", "0"], "--spp"),
    (["--scenes", "1"], "--scenes"), (["--params", "bogus"], "bogus"), (["--size", "17"], "--size"),
    (["--seed", "-1"], "--seed"), (["--real", "MISSING"], "--real"), (["--spread-weight", "-1"], "--spread-weight"),
    (["--spread-weight", "nan"], "--spread-weight"),
])
def test_bad_fit_flag(tmp_path, capsys, inputs, flags, name):
    out = tmp_path / "out"
    flags = [str(tmp_path / "missing") if f == "MISSING" else f for f in flags]
    refused(capsys, ["fit-scene", CYLINDER, "--phi", inputs["root"] / "autoencoder_empty", "--real",
                     inputs["chips"], "--out", out, "--steps", "1", "--spp", "1", *flags], name, out)


# ------------------------------------------------------------------------------------------ training flags

TRAIN_FLAGS = [
    (["--lr", "nan"], "--lr"), (["--lr", "-1"], "--lr"), (["--lr", "inf"], "--lr"), (["--lr", "0"], "--lr"),
    (["--betas", "2", "2"], "--betas"), (["--betas", "-0.1", "0.9"], "--betas"), (["--betas", "nan", "0.9"], "--betas"),
    (["--n-critic", "0"], "--n-critic"), (["--n-critic", "-1"], "--n-critic"),
    (["--batch", "0"], "--batch"), (["--batch", "-4"], "--batch"),
    (["--size", "17"], "--size"), (["--size", "0"], "--size"),
    (["--steps", "0"], "--steps"), (["--steps", "-5"], "--steps"), (["--seed", "-1"], "--seed"),
    (["--phi-weight", "nan"], "--phi-weight"), (["--phi-weight", "-1"], "--phi-weight"),
    (["--phi-margin", "inf"], "--phi-margin"),
]


@pytest.mark.parametrize("flags, name", TRAIN_FLAGS, ids=[" ".join(f) for f, _ in TRAIN_FLAGS])
def test_bad_train_flag(tmp_path, capsys, inputs, flags, name):
    out = tmp_path / "run"
    refused(capsys, ["train", "sasgan", "--real", inputs["chips"], "--renders", inputs["chips"], "--phi",
                     inputs["root"] / "autoencoder_empty", "--out", out, "--steps", "1", "--size", "16",
                     "--batch", "2", "--device", "cpu", *flags], name, out)


@pytest.mark.parametrize("kind", ["autoencoder", "dcgan"])
@pytest.mark.parametrize("folder", ["missing", "file", "empty", "junk", "texts"])
def test_bad_train_folder(tmp_path, capsys, inputs, kind, folder):
    real = tmp_path / "missing" if folder == "missing" else inputs[folder]
    out = tmp_path / "run"
    refused(capsys, ["train", kind, "--real", real, "--out", out, "--steps", "1", "--size", "16", "--batch", "2",
                     "--device", "cpu"], (str(real), "--real"), out)


# ------------------------------------------------------------------------------------------ checkpoints

CHECKPOINTS = ["empty", "truncated", "random", "pickle_code", "torch_code", "other_net", "not_dict", "torch_list",
               "torch_no_state"]
RUNS = CHECKPOINTS + ["no_checkpoint", "bad_config", "other_kind", "missing"]


def _run(inputs, kind: str, name: str) -> Path:
    if name == "other_kind":
        return inputs["root"] / "dcgan_run"
    if name == "missing":
        return inputs["root"] / "no_such_run"
    return inputs["root"] / (f"{kind}_{name}" if name in CHECKPOINTS else f"sasgan_{name}")


@pytest.mark.parametrize("name", RUNS)
def test_bad_generator_translate(tmp_path, capsys, inputs, name):
    run, out = _run(inputs, "sasgan", name), tmp_path / "out"
    refused(capsys, ["translate", "--generator", run, "--in", inputs["chips"], "--out", out, "--device", "cpu"],
            str(run), out)


@pytest.mark.parametrize("name", RUNS)
def test_bad_generator_generate(tmp_path, capsys, inputs, name):
    run, out = _run(inputs, "sasgan", name), tmp_path / "out"
    refused(capsys, ["generate", CYLINDER, "--generator", run, "--out", out, *TINY, "--device", "cpu"],
            str(run), out)


@pytest.mark.parametrize("name", RUNS)
def test_bad_phi_evaluate(tmp_path, capsys, inputs, name):
    run, out = _run(inputs, "autoencoder", name), tmp_path / "out"
    refused(capsys, ["evaluate", "--real", inputs["chips"], "--set", f"a={inputs['chips']}", "--phi", run,
                     "--out", out, "--device", "cpu"], str(run), out)


# ------------------------------------------------------------------------------------------ evaluate, sheet

@pytest.mark.parametrize("flags, name", [
    (["--bootstrap", "1"], "--bootstrap"), (["--bootstrap", "0"], "--bootstrap"), (["--seed", "-1"], "--seed"),
    (["--set", "=x"], "--set"), (["--set", "a=MISSING"], "--set"), (["--set", "real=CHIPS"], "--set"),
    (["--real", "MISSING"], "--real"), (["--preset", str(CYLINDER)], "--generator"),
])
def test_bad_evaluate_flag(tmp_path, capsys, inputs, flags, name):
    out = tmp_path / "out"
    subst = {"MISSING": str(tmp_path / "missing"), "CHIPS": str(inputs["chips"])}
    flags = [f.replace("MISSING", subst["MISSING"]).replace("CHIPS", subst["CHIPS"]) for f in flags]
    argv = ["evaluate", "--real", inputs["chips"], "--phi", inputs["root"] / "autoencoder_empty", "--out", out,
            "--device", "cpu"]
    if not any(f.startswith("--set") for f in flags):
        argv += ["--set", f"a={inputs['chips']}"]
    refused(capsys, argv + flags, name, out)


@pytest.mark.parametrize("flags, folder, name", [
    (["--columns", "0"], "chips", "--columns"), (["--columns", "-2"], "chips", "--columns"),
    (["--limit", "0"], "chips", "--limit"), (["--limit", "nan"], "chips", "--limit"),
    ([], "empty", "empty"), ([], "junk", "junk"), ([], "texts", "texts"), ([], "missing", "missing"),
    ([], "file", "a_file"),
])
def test_bad_sheet(tmp_path, capsys, inputs, flags, folder, name):
    path = tmp_path / "missing" if folder == "missing" else inputs[folder]
    out = tmp_path / "sheet.png"
    refused(capsys, ["sheet", path, "--out", out, *flags], name, None)
    assert not out.exists()


def test_sheet_skips_a_bomb_with_one_warning(tmp_path, capsys, inputs):
    """One unusable image among good ones is skipped with a warning; the sheet is still made."""
    folder = tmp_path / "chips"
    for p in inputs["chips"].iterdir():
        (folder / p.name).parent.mkdir(exist_ok=True)
        (folder / p.name).write_bytes(p.read_bytes())
    Image.new("1", (20000, 20000)).save(folder / "bomb.png")  # 400 M pixels, 50 kB on disk
    assert main(["sheet", str(folder), "--out", str(tmp_path / "s.png")]) == 0
    err = capsys.readouterr().err
    assert "bomb.png" in err and "Traceback" not in err and len(err.strip().splitlines()) <= 2, err
    assert (tmp_path / "s.png").is_file()


# ------------------------------------------------------------------------------------------ the parser itself

@pytest.mark.parametrize("argv, name", [
    ([], "COMMAND"), (["bogus"], "bogus"), (["render"], "preset"), (["train"], "KIND"),
    (["render", str(CYLINDER), "--out"], "--out"), (["render", str(CYLINDER), "--out", "x", "--nope"], "--nope"),
])
def test_bad_command_line(capsys, argv, name):
    refused(capsys, argv, name, None)


# ------------------------------------------------------------------------------------------ real subprocesses

SUBPROCESS = [
    ([], "COMMAND"),
    (["render", "/dev/zero", "--out", "OUT"], "/dev/zero"),
    (["render", str(CYLINDER), "--out", "OUT", "--seed", "-1"], "--seed"),
    (["render", "NAN_PRESET", "--out", "OUT", *TINY], "targets[0].yaw"),
    (["train", "autoencoder", "--real", "CHIPS", "--out", "OUT", "--lr", "nan"], "--lr"),
    (["translate", "--generator", "CODE_RUN", "--in", "CHIPS", "--out", "OUT", "--device", "cpu"], "sasgan_torch_code"),
    (["sheet", "CHIPS", "--columns", "0"], "--columns"),
    (["evaluate", "--real", "CHIPS", "--set", "a=CHIPS", "--phi", "X", "--out", "OUT", "--bootstrap", "1"],
     "--bootstrap"),
    (["fit-scene", str(CYLINDER), "--phi", "X", "--real", "CHIPS", "--out", "OUT", "--steps", "0"], "--steps"),
]


@pytest.mark.parametrize("argv, name", SUBPROCESS, ids=[" ".join(a[:2]) or "none" for a, _ in SUBPROCESS])
def test_bad_input_in_a_real_process(tmp_path, inputs, argv, name):
    out = tmp_path / "out"
    nan_preset = preset(tmp_path, "[[targets]]\nyaw = nan\n")
    subst = {"OUT": str(out), "CHIPS": str(inputs["chips"]), "NAN_PRESET": str(nan_preset),
             "CODE_RUN": str(inputs["root"] / "sasgan_torch_code"), "X": str(tmp_path)}
    argv = [a.replace("CHIPS", subst["CHIPS"]) if "CHIPS" in a else subst.get(a, a) for a in argv]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("SASMI_DEBUG", None)
    done = subprocess.run([sys.executable, "-m", "sasmi", *argv], capture_output=True, text=True, timeout=120,
                          env=env, cwd=tmp_path)
    assert_refused(done.returncode, done.stderr, (name,), out)
    assert done.stdout == ""


def test_a_bug_is_one_line_and_exit_1(capsys, monkeypatch):
    """Genuine bugs stay visible (exit 1, a hint to SASMI_DEBUG) without a traceback."""
    from sasmi.cli import render as render_cmd

    monkeypatch.setattr(render_cmd, "run_render", lambda args: {}["bug"])
    parser_run = main(["render", str(CYLINDER), "--out", "/tmp/unused-sasmi-out"])
    err = capsys.readouterr().err
    assert parser_run == 1 and "internal error: KeyError" in err and "SASMI_DEBUG=1" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 2
    monkeypatch.setenv("SASMI_DEBUG", "1")
    with pytest.raises(KeyError):
        main(["render", str(CYLINDER), "--out", "/tmp/unused-sasmi-out"])


# ------------------------------------------------------------------------------------------ image files

def _png_bytes(shape=(64, 64)) -> bytes:
    import io

    buf = io.BytesIO()
    Image.fromarray(np.random.default_rng(0).integers(0, 255, shape, dtype=np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _npy_header_only(path: Path) -> None:
    with open(path, "wb") as f:  # claims 10^10 float32 values, holds 64 bytes
        np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": (100000, 100000)})
        f.write(b"\0" * 64)


BAD_IMAGES = {
    "bomb.png": (lambda p: Image.new("1", (20000, 20000)).save(p), "decompression bomb"),
    "big.png": (lambda p: Image.new("1", (9000, 9000)).save(p), "too large"),
    "truncated.png": (lambda p: p.write_bytes(_png_bytes()[:-200]), "cannot read image"),
    "half.png": (lambda p: p.write_bytes(_png_bytes()[: len(_png_bytes()) // 2]), "cannot read image"),
    "empty.png": (lambda p: p.write_bytes(b""), "cannot read image"),
    "text.jpg": (lambda p: p.write_text("hello"), "cannot read image"),
    "nan.npy": (lambda p: np.save(p, np.full((8, 8), np.nan, np.float32)), "NaN"),
    "inf.npy": (lambda p: np.save(p, np.full((8, 8), np.inf)), "NaN or infinite"),
    "nan.tiff": (lambda p: __import__("tifffile").imwrite(p, np.full((8, 8), np.nan, np.float32)), "NaN"),
    "complex.npy": (lambda p: np.save(p, np.zeros((8, 8), np.complex64)), "pixel type"),
    "object.npy": (lambda p: np.save(p, np.array([{}, 1], dtype=object), allow_pickle=True), "cannot read image"),
    "header.npy": (_npy_header_only, "cannot read image"),  # the mapped file is shorter than its header says
    "shape.npy": (lambda p: np.save(p, np.zeros((2, 3, 4, 5), np.float32)), "2-D"),
    "zero-width.npy": (lambda p: np.save(p, np.zeros((0, 8), np.float32)), "2-D"),
    "folder.png": (lambda p: p.mkdir(), "not a regular file"),
    "dev-zero.png": (lambda p: p.symlink_to("/dev/zero"), "not a regular file"),
    "missing.png": (lambda p: None, "cannot read image"),
}


@pytest.mark.parametrize("name", BAD_IMAGES)
def test_unusable_image_is_a_one_line_error_naming_it(tmp_path, name):
    from sasmi.errors import SasmiError
    from sasmi.images import read_gray

    make, words = BAD_IMAGES[name]
    make(tmp_path / name)
    with pytest.raises(SasmiError) as e:
        read_gray(tmp_path / name)
    assert name in str(e.value) and words in str(e.value) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("mode", ["1", "L", "LA", "P", "RGB", "RGBA", "CMYK", "I", "I;16", "F"])
def test_every_pil_mode_reads_as_gray_in_unit_range(tmp_path, mode):
    from sasmi.images import read_gray

    path = tmp_path / ("x.tiff" if mode in ("CMYK", "F", "I") else "x.png")
    Image.new(mode, (8, 6)).save(path)
    a = read_gray(path)
    assert a.shape == (6, 8) and a.dtype == np.float32 and 0 <= a.min() <= a.max() <= 1


def test_read_folder_skips_unusable_with_one_line_each(tmp_path, capsys):
    from sasmi.errors import SasmiError
    from sasmi.images import read_folder

    good = _png_bytes((16, 16))
    for name in ("a.png", "b.png"):
        (tmp_path / name).write_bytes(good)
    for name in ("bomb.png", "nan.npy", "truncated.png"):
        BAD_IMAGES[name][0](tmp_path / name)
    paths, images = read_folder(tmp_path)
    err = capsys.readouterr().err.strip().splitlines()
    assert [p.name for p in paths] == ["a.png", "b.png"] and all(i.shape == (16, 16) for i in images)
    assert len(err) == 4 and "skipped 3 of 5 images" in err[-1], err
    assert all(line.startswith("sasmi: warning: skipped ") for line in err)
    for name in ("a.png", "b.png"):
        (tmp_path / name).unlink()
    with pytest.raises(SasmiError, match="no usable image"):
        read_folder(tmp_path)
    (tmp_path / "empty").mkdir()
    with pytest.raises(SasmiError, match="no image files"):
        read_folder(tmp_path / "empty")


# ------------------------------------------------------------------------------------------ the types themselves

def test_argparse_types_parse_check_and_keep_explicit_types(tmp_path):
    import argparse

    from sasmi.cli.arguments import apply_limits, creatable, flag, ranged
    from sasmi.limits import Range

    assert flag("--size")("32") == 32 and flag("--lr")("0.5") == 0.5
    for convert, text in [(flag("--size"), "40"), (flag("--count"), "0"), (flag("--lr"), "nan"),
                          (ranged(Range(None, None, "")), "inf"), (ranged(Range(0, 9, "", int, 3)), "4"),
                          (flag("--seed"), "1e3")]:
        with pytest.raises(argparse.ArgumentTypeError):
            convert(text)
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int)
    parser.add_argument("--out", type=Path)
    apply_limits(parser)
    args = parser.parse_args(["--seed", "7", "--out", str(tmp_path / "a" / "b")])
    assert args.seed == 7 and args.out == tmp_path / "a" / "b"
    with pytest.raises(SystemExit):
        parser.parse_args(["--seed", "-1"])
    own = argparse.ArgumentParser()
    own.add_argument("--count", type=ranged(Range(5, 6, "", int)))  # a range of its own beside limits.FLAGS
    with pytest.raises(TypeError, match="limits.FLAGS"):
        apply_limits(own)
    with pytest.raises(argparse.ArgumentTypeError, match="is a file"):
        (tmp_path / "f").write_text("")
        creatable(str(tmp_path / "f" / "x"))


def test_range_messages_state_the_reason():
    from sasmi.errors import SasmiError
    from sasmi.limits import FIELDS, FLAGS, check_render_cost

    with pytest.raises(SasmiError, match=r"sonar.emitters: 2000 is out of range \(allowed: <= 1024; render time"):
        FIELDS["sonar.emitters"].check(2000, "sonar.emitters")
    assert all(r.why for r in [*FLAGS.values(), *FIELDS.values()])
    check_render_cost(256, 4096)
    with pytest.raises(SasmiError, match="--size and --spp"):
        check_render_cost(1024, 2048)
