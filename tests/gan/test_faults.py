"""Faults during training: a full disk at a checkpoint is one line, exit 2, the last good checkpoint kept; SIGTERM
stops after the step in hand with a checkpoint; either way a resume ends where an uninterrupted run ends."""
from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from sasmi.cli import main as cli

TRAIN = ["train", "autoencoder", "--size", "32", "--batch", "4", "--threads", "1"]


def _weights(run: Path) -> dict[str, torch.Tensor]:
    saved = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
    return saved["step"], saved["state"]["autoencoder"]


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_a_full_disk_at_a_checkpoint_is_one_line_and_the_rerun_ends_as_an_unbroken_run(tmp_path, real_chips,
                                                                                         monkeypatch, capsys):
    args = [*TRAIN, "--real", str(real_chips / "targets"), "--steps", "20", "--checkpoint-every", "10"]
    assert cli.main([*args, "--out", str(tmp_path / "unbroken")]) == 0
    writes, real_write = [], Path.write_bytes

    def full_at_the_second_checkpoint(self, data):
        if self.parent.name == "checkpoints":
            writes.append(self)
            if len(writes) == 2:  # the first is last.pt at step 0; the second best.pt at step 10
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
        return real_write(self, data)

    monkeypatch.setattr(Path, "write_bytes", full_at_the_second_checkpoint)
    run = tmp_path / "run"
    capsys.readouterr()
    assert cli.main([*args, "--out", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "checkpoints/best.pt: no space left on the disk for its" in err and "MB free" in err
    assert not [p for p in (run / "checkpoints").iterdir() if p.name.startswith(".")]  # no temporary file left
    assert _weights(run)[0] == 0  # last.pt: the last good state
    monkeypatch.setattr(Path, "write_bytes", real_write)
    assert cli.main([*args, "--out", str(run), "--resume"]) == 0
    step, weights = _weights(run)
    assert step == 20 and _same(weights, _weights(tmp_path / "unbroken")[1])


@pytest.mark.slow
def test_sigterm_stops_after_a_step_with_a_checkpoint_and_the_resume_is_exact(tmp_path, real_chips):
    command = [sys.executable, "-m", "sasmi", *TRAIN, "--real", str(real_chips / "targets"), "--steps", "100000",
               "--out", str(tmp_path / "run")]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (tmp_path / "run" / "tb").is_dir() and time.monotonic() < deadline:  # the loop has begun
        time.sleep(0.2)
    time.sleep(2.0)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM, err
    last = err.strip().splitlines()[-1].split("\r")[-1]
    step, weights = _weights(tmp_path / "run")
    assert last == (f"sasmi train: stopped by SIGTERM after step {step}, saved in {tmp_path / 'run'}/checkpoints/last.pt; "
                    "rerun the command (sasmi train: with --resume) to continue")
    assert 0 < step < 100000
    more = ["--steps", str(step + 5)]
    assert cli.main([*TRAIN, "--real", str(real_chips / "targets"), *more, "--out", str(tmp_path / "run"), "--resume"]) == 0
    assert cli.main([*TRAIN, "--real", str(real_chips / "targets"), *more, "--out", str(tmp_path / "unbroken")]) == 0
    assert _same(_weights(tmp_path / "run")[1], _weights(tmp_path / "unbroken")[1])


def test_a_second_training_in_a_busy_folder_is_refused_in_one_line(tmp_path, real_chips, capsys):
    from sasmi.images import FolderLock

    args = [*TRAIN, "--real", str(real_chips / "targets"), "--steps", "2", "--out", str(tmp_path / "run")]
    assert cli.main(args) == 0
    held = FolderLock(tmp_path / "run", "training")  # as another process's training would hold it
    before = _weights(tmp_path / "run")
    capsys.readouterr()
    assert cli.main([*args[:-4], "--steps", "4", "--out", str(tmp_path / "run"), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"sasmi (pid {os.getpid()}) is training in this folder" in err
    assert _same(_weights(tmp_path / "run")[1], before[1])  # untouched
    held.release()
    assert cli.main([*args[:-4], "--steps", "4", "--out", str(tmp_path / "run"), "--resume"]) == 0
    assert _weights(tmp_path / "run")[0] == 4


@pytest.mark.slow
def test_kill_9_anywhere_loses_at_most_the_steps_since_the_last_checkpoint(tmp_path, real_chips):
    """SIGKILL cannot be caught: what survives is the last checkpoint, written under a temporary name and renamed."""
    args = [*TRAIN, "--real", str(real_chips / "targets"), "--checkpoint-every", "7"]
    process = subprocess.Popen([sys.executable, "-m", "sasmi", *args, "--steps", "100000", "--out", str(tmp_path / "run")],
                               stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (tmp_path / "run" / "tb").is_dir() and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(2.5)
    process.kill()
    process.wait(timeout=60)
    step = _weights(tmp_path / "run")[0]  # a whole checkpoint, whatever the kill interrupted
    assert step % 7 == 0 and step > 0
    stale = tmp_path / "run" / "checkpoints" / ".last.pt.x1y2z3.tmp.pt"  # as a kill inside a checkpoint write leaves
    stale.write_bytes(b"half a checkpoint")
    # the lock died with the process: the resume may take the folder
    assert cli.main([*args, "--steps", str(step + 10), "--out", str(tmp_path / "run"), "--resume"]) == 0
    assert not stale.exists()
    assert cli.main([*args, "--steps", str(step + 10), "--out", str(tmp_path / "unbroken")]) == 0
    assert _same(_weights(tmp_path / "run")[1], _weights(tmp_path / "unbroken")[1])


def test_a_training_that_clearly_will_not_fit_is_refused_before_any_work(tmp_path, real_chips, monkeypatch, capsys):
    import shutil

    args = [*TRAIN, "--real", str(real_chips / "targets"), "--steps", "2"]
    real_usage = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda path: real_usage(path)._replace(free=1000))
    out = tmp_path / "run"
    assert cli.main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{out}: autoencoder checkpoints need about" in err, err
    assert "its disk has 1 kB free" in err and not out.exists()
    monkeypatch.undo()
    assert cli.main([*args, "--out", str(out)]) == 0
    # the estimate is a checkpoint's size once trained (optimiser moments included), to a few per cent
    from sasmi.gan.kinds.autoencoder import AUTOENCODER
    from sasmi.gan.loop import checkpoint_bytes, resolve_config

    cfg = resolve_config(AUTOENCODER, out, {}, resume=True)
    phases = AUTOENCODER.build(cfg, {"real": real_chips / "targets"}, torch.device("cpu"))
    assert checkpoint_bytes(phases.state) == pytest.approx((out / "checkpoints" / "last.pt").stat().st_size, rel=0.05)
