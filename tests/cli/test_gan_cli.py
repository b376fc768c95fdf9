"""`sasmi train` and `sasmi translate` from the command line: bad input is one line, exit 2, nothing written."""
import os
from pathlib import Path

import numpy as np
import pytest

from sasmi.cli.main import main
from sasmi.images import write_gray


@pytest.fixture
def images(tmp_path):
    folder = tmp_path / "images"
    rng = np.random.default_rng(0)
    for i in range(4):
        write_gray(folder / f"{i}.png", rng.random((32, 32)))
    return folder


def _fails_cleanly(capsys, argv, out, match):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"sasmi {argv[0]}: error: ") and match in err, err
    assert not Path(out).exists()


@pytest.mark.parametrize("kind", ["autoencoder", "dcgan"])
def test_train_bad_input(tmp_path, capsys, images, kind):
    out = tmp_path / "run"
    (tmp_path / "empty").mkdir()
    _fails_cleanly(capsys, ["train", kind, "--real", str(tmp_path / "missing"), "--out", str(out)], out, "not a folder")
    _fails_cleanly(capsys, ["train", kind, "--real", str(tmp_path / "empty"), "--out", str(out)], out,
                   "no readable image")
    _fails_cleanly(capsys, ["train", kind, "--real", str(images), "--out", str(out), "--size", "40"], out,
                   "multiple of 16")
    _fails_cleanly(capsys, ["train", kind, "--real", str(images), "--out", str(out), "--resume"], out,
                   "nothing to resume")


def test_train_sasgan_bad_phi_run(tmp_path, capsys, images):
    out = tmp_path / "run"
    _fails_cleanly(capsys, ["train", "sasgan", "--real", str(images), "--renders", str(images),
                            "--phi", str(tmp_path), "--out", str(out), "--size", "32"], out, "not a training run")


def test_translate_bad_input(tmp_path, capsys, images):
    out = tmp_path / "out"
    _fails_cleanly(capsys, ["translate", "--generator", str(tmp_path / "nope"), "--in", str(images),
                            "--out", str(out)], out, "not a training run")


def test_train_translate_and_resume_from_the_command_line(tmp_path, capsys, images):
    ae, gan, dc, out = (str(tmp_path / name) for name in ("ae", "gan", "dc", "out"))
    common = ["--real", str(images), "--size", "32", "--batch", "2", "--device", "cpu", "--steps", "2"]
    assert main(["train", "autoencoder", "--out", ae, *common]) == 0
    assert main(["train", "sasgan", "--renders", str(images), "--phi", ae, "--out", gan, *common,
                 "--n-critic", "1", "--phi-margin", "0.3", "--betas", "0.0", "0.9"]) == 0
    assert main(["train", "dcgan", "--out", dc, *common, "--n-critic", "1"]) == 0
    assert len(os.listdir(Path(dc) / "final_samples")) == 256
    assert main(["train", "sasgan", "--renders", str(images), "--phi", ae, "--out", gan, "--real", str(images),
                 "--steps", "3", "--resume"]) == 0
    assert main(["translate", "--generator", gan, "--in", str(images), "--out", out, "--device", "cpu"]) == 0
    assert sorted(f for f in os.listdir(out) if f != ".lock") == ["0.png", "1.png", "2.png", "3.png", "translate.json"]
    capsys.readouterr()
    # a changed setting on resume is refused before anything changes
    assert main(["train", "sasgan", "--renders", str(images), "--phi", ae, "--out", gan, "--real", str(images),
                 "--steps", "4", "--resume", "--phi-margin", "0.5"]) == 2
    assert "phi_margin=0.5 (run has 0.3)" in capsys.readouterr().err


def test_net_flag_picks_network_sizes(tmp_path, images):
    import torch

    out = tmp_path / "dc"
    assert main(["train", "dcgan", "--real", str(images), "--out", str(out), "--size", "32", "--batch", "2",
                 "--steps", "1", "--n-critic", "1", "--net", "paper", "--device", "cpu"]) == 0
    config = torch.load(out / "checkpoints" / "last.pt", weights_only=True)["config"]
    assert config["critic"] == {"width": 64, "patch": False, "phi_features": False, "standardise": False}
    assert config["dcgan"]["width"] == 64
