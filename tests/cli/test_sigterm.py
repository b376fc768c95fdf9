"""SIGTERM to a command outside a training: one line, exit 143, no traceback; the rerun completes the set that an
uninterrupted run writes, byte for byte (trainings stop at a step instead: tests/gan/test_faults.py)."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from sasmi.images import list_images


@pytest.mark.slow
def test_a_render_terminated_midway_says_so_and_its_rerun_completes_the_same_set(tmp_path):
    command = [sys.executable, "-m", "sasmi", "render", "cylinder_chip", "--count", "300", "--size", "32",
               "--spp", "2"]
    process = subprocess.Popen([*command, "--out", str(tmp_path / "cut")], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (tmp_path / "cut" / "labels").is_dir() or len(list((tmp_path / "cut" / "labels").iterdir())) < 20:
        assert time.monotonic() < deadline, "fewer than 20 chips in 120 s"
        assert process.poll() is None, process.communicate()[1]  # its stderr: why it stopped early
        time.sleep(0.1)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err
    assert err.strip().split("\r")[-1].splitlines()[-1] == (
        "sasmi render: terminated (SIGTERM); finished work is kept: rerun the same command to continue")
    assert len(list((tmp_path / "cut" / "labels").iterdir())) < 300  # stopped midway
    for out in ("cut", "whole"):
        subprocess.run([*command, "--out", str(tmp_path / out)], check=True, capture_output=True, timeout=300)
    cut, whole = list_images(tmp_path / "cut" / "images"), list_images(tmp_path / "whole" / "images")
    assert [p.name for p in cut] == [p.name for p in whole] and len(cut) == 300
    assert all(a.read_bytes() == b.read_bytes() for a, b in zip(cut, whole))
    assert (tmp_path / "cut" / "labels.jsonl").read_bytes() == (tmp_path / "whole" / "labels.jsonl").read_bytes()


@pytest.mark.slow
def test_a_calibration_terminated_midway_stops_after_its_trial_and_the_rerun_continues(tmp_path, real_chips):
    import optuna

    command = [sys.executable, "-m", "sasmi", "calibrate", "--real", str(real_chips / "targets"), "--preset",
               "muscle_paper", "--params", "post.gain,post.speckle_looks", "--chips", "8", "--size", "32",
               "--trials", "12", "--searches", "2", "--profile-trials", "0", "--final-chips", "16",
               "--out", str(tmp_path / "run")]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    storage = f"sqlite:///{tmp_path / 'run' / 'study.db'}"

    def trials() -> dict[str, list]:
        """Each search's trials."""
        try:
            return {name: optuna.load_study(study_name=name, storage=storage).trials
                    for name in optuna.get_all_study_names(storage)}
        except Exception:  # the study is not made yet
            return {}

    deadline = time.monotonic() + 180
    while sum(map(len, trials().values())) < 4:
        assert time.monotonic() < deadline, "fewer than 4 trials in 180 s"
        assert process.poll() is None, process.communicate()[1]  # its stderr: why it stopped early
        time.sleep(0.2)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err and "rerun the same command to continue" in err.strip().splitlines()[-1]
    before = {name: [t.params for t in ts] for name, ts in trials().items()}
    assert 4 <= sum(map(len, before.values())) < 12 and not (tmp_path / "run" / "preset.toml").exists()
    subprocess.run(command, check=True, capture_output=True, timeout=300)
    after = trials()
    assert sum(map(len, after.values())) == 12 and set(after) == {"calibrate", "calibrate-1"}
    assert all([t.params for t in after[name][:len(ts)]] == ts for name, ts in before.items())
    assert (tmp_path / "run" / "preset.toml").is_file()
