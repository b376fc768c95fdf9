"""`torchrun --nproc_per_node 2 -m sasmi train ...` (gloo, 2 CPU processes) trains the run one
process trains at the same global batch (gan/distributed.py)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from sasmi.cli.main import main
from sasmi.images import write_gray

SIZE = 32


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ddp")
    rng = np.random.default_rng(0)
    for folder in ("real", "renders/images"):
        for i in range(8):
            write_gray(root / folder / f"{i}.png", rng.random((SIZE, SIZE)))
    assert main(["train", "autoencoder", "--real", str(root / "real"), "--out", str(root / "phi"), "--steps", "2",
                 "--size", str(SIZE), "--batch", "4"]) == 0
    return root


def torchrun(argv: list[str], cwd: Path) -> None:
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                           "-m", "sasmi", *argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]


def weights(run: Path, name: str) -> torch.Tensor:
    state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)["state"][name]
    return torch.cat([v.flatten() for v in state.values() if v.is_floating_point()])


def test_two_processes_train_the_autoencoder_one_process_trains(data, monkeypatch):
    argv = ["train", "autoencoder", "--real", "real", "--steps", "4", "--size", str(SIZE), "--batch", "4"]
    torchrun([*argv, "--out", "ae2"], data)
    monkeypatch.chdir(data)
    assert main([*argv, "--out", "ae1"]) == 0
    assert torch.allclose(weights(data / "ae1", "autoencoder"), weights(data / "ae2", "autoencoder"), atol=1e-5)
    # only the main process wrote: one set of checkpoints, one TensorBoard log
    assert len(list((data / "ae2" / "tb").iterdir())) == 1


def test_two_processes_train_the_sas_gan_one_process_trains_at_the_same_global_batch(data, monkeypatch):
    """GP, augmentation and the data stream all run sliced; Adam's first steps turn the order of
    float sums into sign flips of near-zero gradients, so 'the same' is measured against how far
    a run at another global batch lands."""
    argv = ["train", "sasgan", "--real", "real", "--renders", "renders", "--phi", "phi", "--steps", "2",
            "--size", str(SIZE), "--n-critic", "2", "--augment"]
    torchrun([*argv, "--batch", "4", "--out", "gan2"], data)
    monkeypatch.chdir(data)
    assert main([*argv, "--batch", "4", "--out", "gan1"]) == 0
    assert main([*argv, "--batch", "2", "--out", "gan1_half"]) == 0
    for name in ("generator", "critic"):
        one = weights(data / "gan1", name)
        same = (weights(data / "gan2", name) - one).abs().median()
        other = (weights(data / "gan1_half", name) - one).abs().median()
        assert same < other / 5, (name, float(same), float(other))


def test_the_global_batch_must_divide_among_the_processes(data):
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                           "-m", "sasmi", "train", "autoencoder", "--real", "real", "--out", "odd", "--steps", "1",
                           "--size", str(SIZE), "--batch", "3"], cwd=data, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode != 0
    assert "--batch 3: the global batch must divide evenly among the 2 processes" in done.stderr
    assert not (data / "odd" / "checkpoints").exists()
