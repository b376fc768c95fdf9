"""Two commands on one output folder: translations, YOLO exports and calibrations take RUN/.lock, so a
second one is refused in one line (exit 2) and the folder is left as the first one writes it."""
from __future__ import annotations

import os

import pytest

from sasmi.cli import main as cli
from sasmi.images import FolderLock
from sasmi.weights import shipped


def _commands(render_set, out, real=None):
    return {
        "translating": ["translate", "--in", str(render_set), "--out", str(out), "--generator", str(shipped("sasgan"))],
        "exporting": ["export", str(render_set), "--format", "yolo", "--out", str(out)],
        "running sasmi calibrate": ["calibrate", "--real", str(real), "--preset", "muscle_paper", "--chips", "8",
                                    "--trials", "1", "--size", "32", "--out", str(out)],
    }


@pytest.mark.parametrize("what", ["translating", "exporting", "running sasmi calibrate"])
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
    FolderLock(out, "translating").release()
