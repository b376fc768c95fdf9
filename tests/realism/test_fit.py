"""`sasmi fit`: every stage at 32 px on toy chips, resumable, refuses another plan in the same folder."""
from __future__ import annotations

import json
import re

import numpy as np
import torch

from conftest import disk_full_at, temporary_files
from sasmi.realism import fit as fitting
from sasmi.cli.main import main
from sasmi.images import read_gray, write_gray


def _chips(folder, n, seed):
    rng = np.random.default_rng(seed)
    for i in range(n):
        image = rng.gamma(6.0, 0.3 / 6.0, (32, 32)).astype(np.float32)
        image[12:16, 12:15] = 0.8  # a highlight with its shadow to the right, as in the real chips
        image[12:16, 15:24] *= 0.1
        write_gray(folder / f"{i:03d}.png", image)
    return folder


def test_fit_runs_every_stage_then_resumes_without_retraining(tmp_path, capsys):
    real, validation = _chips(tmp_path / "real", 12, 0), _chips(tmp_path / "val", 12, 1)
    out = tmp_path / "run"
    argv = ["fit", "--real", str(real), "--validation", str(validation), "--out", str(out), "--minutes", "0.05",
            "--size", "32", "--count", "8", "--preset", "cylinder_chip"]
    assert main(argv) == 0
    for folder in ("phi", "renders", "sasgan", "translated"):
        assert (out / folder).is_dir(), folder
    assert len(list((out / "translated" / "images").glob("*.png"))) == 8
    metrics = json.loads((out / "report" / "metrics.json").read_text())
    assert set(metrics["realism"]) == {"real→real", "sasgan", "renders", "train_real"} and "image_statistics" in metrics
    assert metrics["sets"]["train_real"] == {"dir": str(real), "n": 12}  # the reference: the GAN's own real chips
    state = json.loads((out / "fit.json").read_text())
    assert state["done"] == ["phi", "renders", "sasgan", "translated", "report"]
    err = capsys.readouterr().err
    assert "[3/5 sasgan]" in err and "min of the budget left" in err
    # the default recipe, real_levels: each translated chip takes a real chip's gray levels
    generator = torch.load(out / "sasgan" / "checkpoints" / "last.pt", weights_only=True)["config"]["generator"]
    assert generator["donor_levels_after"] and generator["donor_shadow"] == 0.4
    real_medians = np.array([np.median(read_gray(path)) for path in real.glob("*.png")])
    for path in (out / "translated" / "images").glob("*.png"):
        assert np.abs(real_medians - np.median(read_gray(path))).min() < 0.005, path

    # the stage command with the same recipe trains the same run: every setting but the step count
    trained = json.loads((out / "sasgan" / "config.json").read_text())
    stage = tmp_path / "stage"
    assert main(["train", "sasgan", "--recipe", "real_levels", "--real", str(real), "--renders", str(out / "renders"),
                 "--phi", str(out / "phi"), "--size", "32", "--seed", "0", "--steps", "1", "--out", str(stage)]) == 0
    staged = json.loads((stage / "config.json").read_text())
    assert staged["config"].pop("steps") == 1 and trained["config"].pop("steps") > 1
    assert staged["config"] == trained["config"] and staged["inputs"] == trained["inputs"]

    last = out / "sasgan" / "checkpoints" / "last.pt"
    stamp = last.stat().st_mtime_ns
    assert main(argv) == 0  # a rerun finds every stage done
    assert last.stat().st_mtime_ns == stamp
    # ... and says by how much --minutes must grow before the GAN trains on: a budget raised less changes nothing
    said = re.search(r"trained; --minutes ([0-9.]+) or more trains on", capsys.readouterr().err)
    gan_seconds = json.loads((out / "fit.json").read_text())["seconds"]["sasgan"]
    assert said and fitting.SHARE["sasgan"] * float(said[1]) * 60 - gan_seconds > fitting.MIN_CHUNK_SECONDS
    assert fitting.SHARE["sasgan"] * (float(said[1]) - 0.1) * 60 - gan_seconds <= fitting.MIN_CHUNK_SECONDS

    assert main([*argv[:-2], "--preset", "seafloor_only"]) == 2  # another plan into the same folder
    assert "only --minutes may change" in capsys.readouterr().err


def test_fit_reuses_a_phi_run_and_refuses_a_bad_recipe(tmp_path, capsys):
    real = _chips(tmp_path / "real", 12, 0)
    first = tmp_path / "first"
    base = ["fit", "--real", str(real), "--minutes", "0.02", "--size", "32", "--count", "8", "--recipe", "baseline"]
    assert main([*base, "--out", str(first)]) == 0
    second = tmp_path / "second"
    assert main([*base, "--out", str(second), "--phi", str(first / "phi")]) == 0
    assert not (second / "phi").exists() and (second / "report" / "metrics.json").is_file()
    # without --validation the report compares with --real itself: no train_real row, a warning
    report = json.loads((second / "report" / "metrics.json").read_text())
    assert "train_real" not in report["realism"] and "optimistic" in (second / "report" / "report.md").read_text()

    recipe = tmp_path / "recipe.toml"
    recipe.write_text("mask_wieght = 3\n")
    assert main([*base, "--out", str(tmp_path / "third"), "--recipe", str(recipe)]) == 2
    err = capsys.readouterr().err
    assert "mask_wieght: not a SAS GAN setting" in err and not (tmp_path / "third").exists()
    recipe.write_text('mask_highlight = "max"\n')
    assert main([*base, "--out", str(tmp_path / "third"), "--recipe", str(recipe)]) == 2
    err = capsys.readouterr().err
    assert f"--recipe {recipe}: mask_highlight = 'max'" in err and not (tmp_path / "third").exists()
    for text, named in (('[critic]\nphi_features = "yes"\n', "critic.phi_features = 'yes': expected bool"),
                        ("n_critic = 2.5\n", "n_critic = 2.5: expected int")):
        recipe.write_text(text)  # a string is truthy: it would have switched the option on
        assert main([*base, "--out", str(tmp_path / "third"), "--recipe", str(recipe)]) == 2
        err = capsys.readouterr().err
        assert f"--recipe {recipe}: its SasganRun cannot be rebuilt ({named})" in err, err
        assert len(err.strip().splitlines()) == 1 and not (tmp_path / "third").exists()


def test_fit_with_floors_lays_the_renders_on_them(tmp_path, capsys):
    real = _chips(tmp_path / "real", 12, 0)
    floors = tmp_path / "floors"
    for i in range(4):
        write_gray(floors / f"f{i}.png", np.random.default_rng(i).gamma(6.0, 0.05, (32, 32)))
    out = tmp_path / "run"
    argv = ["fit", "--real", str(real), "--out", str(out), "--minutes", "0.02", "--size", "32", "--count", "8",
            "--recipe", "baseline", "--floors", str(floors)]
    assert main(argv) == 0
    assert len(list((out / "on_floors" / "images").glob("*.png"))) == 8
    assert (out / "on_floors" / "labels.jsonl").is_file() and (out / "on_floors" / "masks").is_dir()
    assert json.loads((out / "fit.json").read_text())["done"] == ["phi", "renders", "on_floors", "sasgan", "translated",
                                                                  "report"]
    metrics = json.loads((out / "report" / "metrics.json").read_text())
    assert {"sasgan", "renders", "on_floors"} <= set(metrics["realism"])
    assert metrics["sets"]["on_floors"]["dir"] == str(out / "on_floors")
    assert "[3/6 on_floors]" in capsys.readouterr().err


def test_fit_refuses_an_empty_floors_folder_before_writing(tmp_path, capsys):
    real, empty = _chips(tmp_path / "real", 12, 0), tmp_path / "empty"
    empty.mkdir()
    out = tmp_path / "run"
    assert main(["fit", "--real", str(real), "--out", str(out), "--minutes", "0.02", "--size", "32",
                 "--floors", str(empty)]) == 2
    err = capsys.readouterr().err
    assert f"--floors {empty}: no image" in err and "Traceback" not in err and not out.exists()


def test_fit_takes_the_phi_chips_seafloor_as_floors_unless_told_not_to(tmp_path):
    from sasmi.cli.main import build_parser
    from sasmi.realism.fit import FitPlan, with_defaults

    train = tmp_path / "train"
    _chips(train / "targets", 2, 0), _chips(train / "seafloor", 2, 1)
    base = ["fit", "--real", str(train / "targets"), "--out", "run"]

    def plan(*argv):
        args = build_parser().parse_args([*base, *argv])
        return with_defaults(FitPlan(real=args.real, out=args.out, phi_real=args.phi_real,
                                     validation=args.validation, floors=args.floors))

    assert plan("--phi-real", str(train)).floors == str(train / "seafloor")  # `sasmi split`'s layout
    assert plan("--phi-real", str(train), "--no-floors").floors == ""
    assert plan("--phi-real", str(train), "--floors", str(tmp_path / "mine")).floors == str(tmp_path / "mine")
    assert plan().floors == ""  # --real alone: a targets folder has no seafloor/
    assert "floors" not in plan("--no-floors").identity()  # a fit.json without floors matches a --no-floors rerun


def test_fit_reports_on_the_splits_validation_chips_unless_told_otherwise(tmp_path):
    """A command that names only train folders still gets its report on validation chips."""
    from sasmi.cli.main import build_parser
    from sasmi.realism.fit import FitPlan, with_defaults

    split = tmp_path / "split"
    _chips(split / "train" / "targets", 2, 0), _chips(split / "validation" / "targets", 2, 1)
    _chips(tmp_path / "mine", 2, 2)

    def validation(real, *argv):
        args = build_parser().parse_args(["fit", "--real", str(real), "--out", "run", *argv])
        return with_defaults(FitPlan(real=args.real, out=args.out, phi_real=args.phi_real,
                                     validation=args.validation, floors=args.floors)).validation

    assert validation(split / "train" / "targets") == str(split / "validation" / "targets")
    assert validation(split / "train" / "targets", "--validation", str(tmp_path / "mine")) == str(tmp_path / "mine")
    assert validation(tmp_path / "mine") == str(tmp_path / "mine")  # no split beside it: the warning says so
    for chip in (split / "validation" / "targets").iterdir():
        chip.unlink()
    assert validation(split / "train" / "targets") == str(split / "train" / "targets")  # an empty side is no set


def _fit_argv(tmp_path) -> list[str]:
    real, validation = _chips(tmp_path / "real", 12, 0), _chips(tmp_path / "val", 12, 1)
    return ["fit", "--real", str(real), "--validation", str(validation), "--minutes", "0.05", "--size", "32",
            "--count", "8", "--preset", "cylinder_chip"]


def _finished(out) -> bool:
    state = json.loads((out / "fit.json").read_text())
    return (state["done"] == ["phi", "renders", "sasgan", "translated", "report"]
            and len(list((out / "translated" / "images").glob("*.png"))) == 8
            and (out / "report" / "report.md").is_file())


def test_a_full_disk_in_any_stage_of_fit_is_one_line_and_the_rerun_finishes(tmp_path, monkeypatch, capsys):
    """The disk fills at the first file each stage commits, one stage per run, each run resuming the last."""
    argv = [*_fit_argv(tmp_path), "--out", str(tmp_path / "run")]
    for stage in ("phi", "renders", "sasgan", "translated", "report"):
        disk_full_at(monkeypatch, tmp_path / "run" / stage)
        assert main(argv) == 2, stage
        monkeypatch.undo()
        err = capsys.readouterr().err
        last = err.strip().split("\r")[-1].splitlines()[-1]
        assert "No space left on device" in last and "Traceback" not in err, err
        assert not temporary_files(tmp_path / "run"), stage
        state = tmp_path / "run" / "fit.json"
        assert not state.exists() or stage not in json.loads(state.read_text())["done"], stage
    assert main(argv) == 0
    assert _finished(tmp_path / "run")


def test_kill_9_inside_any_stage_of_fit_and_the_rerun_finishes(tmp_path):
    """SIGKILL as each stage writes its first files; the same command then continues and finishes."""
    import subprocess
    import sys
    import time

    argv = [*_fit_argv(tmp_path), "--out", str(tmp_path / "run")]
    out = tmp_path / "run"
    marks = {"phi": out / "phi" / "checkpoints" / "last.pt", "renders": out / "renders" / "images",
             "sasgan": out / "sasgan" / "checkpoints" / "last.pt", "translated": out / "translated" / "images"}
    for stage, mark in marks.items():
        process = subprocess.Popen([sys.executable, "-m", "sasmi", *argv], stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 120
        while not mark.exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        process.kill()
        process.wait(timeout=60)
        assert mark.exists(), stage
    assert main(argv) == 0  # the lock died with the killed process: the rerun takes the folder
    assert _finished(out)
    assert not temporary_files(out)
