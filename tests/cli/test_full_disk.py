"""A full disk in the middle of `generate`, `export` and `evaluate`: one line, exit 2, no file half-written under its
final name, and the rerun on a disk with room ends as an uninterrupted run. Every file sasmi writes is committed by
one rename (sasmi.images.atomic_path); the disk fills at the k-th of them."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import disk_full_at, temporary_files
from sasmi.cli.main import main

PRESET = "cylinder_chip"


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _one_line_no_space(capsys) -> str:
    """The error is one line, the last (progress lines may come before it), with no traceback."""
    err = capsys.readouterr().err
    last = err.strip().split("\r")[-1].splitlines()[-1]
    assert "error: " in last and "No space left on device" in last and "Traceback" not in err, err
    assert err.count("error") == 1, err
    return last


def _fails_when_the_disk_fills(monkeypatch, capsys, command: list[str], out: Path, k: int) -> None:
    """`command` into `out` with the disk full at the k-th rename: one line, exit 2, no temporary file left."""
    seen = disk_full_at(monkeypatch, out, k)
    assert main([*command, "--out", str(out)]) == 2
    _one_line_no_space(capsys)
    assert not temporary_files(out)
    assert len(seen) == k
    monkeypatch.undo()


@pytest.mark.slow
def test_generate_and_export_on_a_full_disk(tmp_path, monkeypatch, capsys):
    args = ["generate", PRESET, "--count", "6", "--spp", "2", "--batch", "2"]
    assert main([*args, "--out", str(tmp_path / "whole")]) == 0
    assert main(["export", str(tmp_path / "whole"), "--format", "coco", "--out", str(tmp_path / "whole.json")]) == 0
    capsys.readouterr()

    out = tmp_path / "cut"
    _fails_when_the_disk_fills(monkeypatch, capsys, args, out, 9)  # in the middle of the chips
    assert main([*args, "--out", str(out)]) == 0  # the rerun completes the set
    assert _files(out) == _files(tmp_path / "whole")

    disk_full_at(monkeypatch, tmp_path / "cut.json", 1)
    capsys.readouterr()
    assert main(["export", str(out), "--format", "coco", "--out", str(tmp_path / "cut.json")]) == 2
    _one_line_no_space(capsys)
    assert not (tmp_path / "cut.json").exists()
    monkeypatch.undo()
    assert main(["export", str(out), "--format", "coco", "--out", str(tmp_path / "cut.json")]) == 0
    cut, whole = (json.loads((tmp_path / name).read_text()) for name in ("cut.json", "whole.json"))
    assert {k: v for k, v in cut.items() if k != "info"} == {k: v for k, v in whole.items() if k != "info"}


@pytest.mark.slow
def test_evaluate_on_a_full_disk(tmp_path, monkeypatch, capsys, real_chips):
    args = ["evaluate", "--real", str(real_chips / "targets"), "--set", f"floors={real_chips / 'seafloor'}",
            "--bootstrap", "5", "--no-two-sample", "--no-cache"]
    disk_full_at(monkeypatch, tmp_path / "report", 2)
    assert main([*args, "--out", str(tmp_path / "report")]) == 2
    _one_line_no_space(capsys)
    assert not temporary_files(tmp_path / "report")
    monkeypatch.undo()
    assert main([*args, "--out", str(tmp_path / "report")]) == 0
    assert (tmp_path / "report" / "report.md").is_file() and (tmp_path / "report" / "metrics.json").is_file()


def test_a_render_that_clearly_will_not_fit_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    import shutil

    real_usage = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real_usage(path)._replace(free=5_000_000))
    out = tmp_path / "renders"
    assert main(["render", PRESET, "--count", "1000", "--size", "128", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{out}: 1000 chips need about 33 MB and its disk has 5 MB free" in err
    assert not out.exists()
    assert main(["render", PRESET, "--count", "2", "--size", "32", "--spp", "2", "--out", str(out)]) == 0  # small: fits


def test_translate_on_a_full_disk(tmp_path, monkeypatch, capsys, render_set):
    from sasmi.weights import shipped

    args = ["translate", "--in", str(render_set), "--generator", str(shipped("sasgan"))]
    assert main([*args, "--out", str(tmp_path / "whole")]) == 0
    capsys.readouterr()
    out = tmp_path / "cut"
    _fails_when_the_disk_fills(monkeypatch, capsys, args, out, 4)  # in the middle of the chips
    assert not (out / "translate.json").exists()
    assert main([*args, "--out", str(out)]) == 0  # the rerun completes the set
    cut, whole = _files(out), _files(tmp_path / "whole")
    assert cut.keys() == whole.keys() and all(cut[k] == whole[k] for k in cut if k != "translate.json")


def test_a_translation_or_export_that_clearly_will_not_fit_is_refused_before_any_work(tmp_path, monkeypatch, capsys,
                                                                                     render_set):
    import shutil

    from sasmi.weights import shipped

    commands = {"translate": ["translate", "--in", str(render_set), "--generator", str(shipped("sasgan"))],
                "export": ["export", str(render_set), "--format", "yolo"]}
    real_usage = shutil.disk_usage
    for name, args in commands.items():
        out = tmp_path / name
        monkeypatch.setattr(shutil, "disk_usage", lambda path: real_usage(path)._replace(free=1000))
        assert main([*args, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"{out}: 8 " in err and "kB and its disk has 1 kB free" in err, err
        assert not out.exists()
        monkeypatch.undo()
        assert main([*args, "--out", str(out)]) == 0
        monkeypatch.setattr(shutil, "disk_usage", lambda path: real_usage(path)._replace(free=1000))
        assert main([*args, "--out", str(out)]) == 0  # a rerun: every chip is there, nothing more to write
        monkeypatch.undo()
        capsys.readouterr()
