"""Two commands on one output folder: translations, YOLO exports, evaluations, fit-scenes and calibrations take
RUN/.lock, so a second one is refused in one line (exit 2) and the folder is left as the first one writes it; a
command that ends removes the lock file, and the folder too if it wrote nothing."""
from __future__ import annotations

import os

import pytest

import sasmi.images
from sasmi.cli import main as cli
from sasmi.errors import SasmiError
from sasmi.images import FolderLock
from sasmi.weights import shipped


def _commands(render_set, out, real=None):
    return {
        "translating": ["translate", "--in", str(render_set), "--out", str(out), "--generator", str(shipped("sasgan"))],
        "exporting": ["export", str(render_set), "--format", "yolo", "--out", str(out)],
        "evaluating": ["evaluate", "--real", str(real), "--set", f"renders={render_set}", "--bootstrap", "5",
                       "--no-two-sample", "--no-cache", "--out", str(out)],
        "running sasmi fit-scene": ["fit-scene", "cylinder_chip", "--real", str(real), "--phi", str(shipped("phi")),
                                    "--steps", "1", "--out", str(out)],
        "running sasmi calibrate": ["calibrate", "--real", str(real), "--preset", "muscle_paper", "--chips", "8",
                                    "--trials", "1", "--size", "32", "--out", str(out)],
    }


@pytest.mark.parametrize("what", ["translating", "exporting", "evaluating", "running sasmi fit-scene",
                                  "running sasmi calibrate"])
def test_a_second_command_on_a_held_folder_is_refused_in_one_line(what, render_set, real_chips, tmp_path, capsys):
    out = tmp_path / "out"
    held = FolderLock(out, what)  # as another process's command would hold it
    capsys.readouterr()
    assert cli.main(_commands(render_set, out, real_chips / "targets")[what]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"sasmi (pid {os.getpid()}) is {what} in this folder" in err, err
    assert sorted(p.name for p in out.iterdir()) == [".lock"]  # nothing written beside the lock
    held.release()


def test_the_lock_is_released_when_the_command_ends(render_set, tmp_path):
    out = tmp_path / "out"
    for _ in range(2):  # the second run finds the folder free again
        assert cli.main(_commands(render_set, out)["translating"]) == 0
        assert not (out / ".lock").exists()  # a finished folder holds only what the command made
    FolderLock(out, "translating").release()


def test_a_command_refused_before_its_first_file_leaves_no_folder(tmp_path, capsys):
    out = tmp_path / "report"
    argv = ["evaluate", "--real", str(tmp_path), "--set", f"none={tmp_path}", "--no-cache", "--out", str(out)]
    assert cli.main(argv) == 2  # no image in --real: refused after the lock is taken
    assert "images" in capsys.readouterr().err and not out.exists()


def test_a_lock_taken_as_its_holder_releases_it_is_never_shared(tmp_path, monkeypatch):
    """The holder removes the lock file as it ends: a command that opened that file just before must not
    count the removed file as held, or a third command would take a new file beside it."""
    first = FolderLock(tmp_path, "training")
    real_flock, calls = sasmi.images.fcntl.flock, []

    def flock(file, operation):
        if not calls:  # between the second command's open and its lock, the first one ends
            calls.append(operation)
            first.release()
        return real_flock(file, operation)

    monkeypatch.setattr(sasmi.images.fcntl, "flock", flock)
    second = FolderLock(tmp_path, "training")
    monkeypatch.undo()
    with pytest.raises(SasmiError, match="is training in this folder"):
        FolderLock(tmp_path, "training")
    second.release()
    assert not (tmp_path / ".lock").exists()
