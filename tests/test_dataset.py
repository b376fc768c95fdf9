"""`sasmi render` output: layout, formats, resume after a kill, refusal to mix runs."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from sasmi.cli import main
from sasmi.images import read_gray

from conftest import REPO

PRESET = str(REPO / "scenes" / "muscle_paper.toml")


def render_cmd(out, count, *extra):
    return [sys.executable, "-m", "sasmi.cli", "render", PRESET, "--out", str(out), "--count", str(count),
            "--size", "32", "--spp", "4", *extra]


def test_layout_and_labels(render_set):
    labels = [json.loads(line) for line in (render_set / "labels.jsonl").read_text().splitlines()]
    assert [entry["index"] for entry in labels] == list(range(8))
    run = json.loads((render_set / "run.json").read_text())
    assert run["variant"] == "llvm_ad_mono" and run["mitsuba"] and run["drjit"] and run["preset"]["sonar"]
    for entry in labels:
        image = np.asarray(Image.open(render_set / entry["image"]))
        mask = np.asarray(Image.open(render_set / entry["mask"]))
        assert image.shape == mask.shape == (32, 32) and image.dtype == np.uint8
        assert set(np.unique(mask)) <= {0, 1, 2}
        t = entry["targets"][0]
        assert {"x", "y", "yaw", "burial", "pixel_centre", "bbox"} <= set(t)
        assert entry["seafloor"]["albedo"] and entry["sonar"]["near_range"] >= 30.0


@pytest.mark.parametrize("fmt, suffix, dtype", [("tiff16", ".tiff", np.uint16), ("npy", ".npy", np.float32)])
def test_other_formats(tmp_path, fmt, suffix, dtype, render_set):
    out = tmp_path / fmt
    assert main(["render", PRESET, "--out", str(out), "--count", "2", "--size", "32", "--spp", "4",
                 "--format", fmt]) == 0
    files = sorted((out / "images").iterdir())
    assert [f.suffix for f in files] == [suffix, suffix]
    png = read_gray(render_set / "images" / "000000.png")
    other = read_gray(files[0])
    assert np.abs(other - png).max() <= 1 / 255 + 1e-6  # same scene, finer quantisation


def test_refuses_to_mix_runs(tmp_path, capsys, render_set):
    out = tmp_path / "mixed"
    assert main(["render", PRESET, "--out", str(out), "--count", "1", "--size", "32", "--spp", "4"]) == 0
    assert main(["render", PRESET, "--out", str(out), "--count", "1", "--size", "32", "--spp", "4", "--seed", "9"]) == 2
    assert "other settings" in capsys.readouterr().err


def test_resume_after_kill_gives_identical_files(tmp_path):
    straight, resumed = tmp_path / "straight", tmp_path / "resumed"
    count = 24
    subprocess.run(render_cmd(straight, count), check=True, capture_output=True, timeout=300)

    proc = subprocess.Popen(render_cmd(resumed, count), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and len(list((resumed / "labels").glob("*.json"))) < 4:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done_at_kill = len(list((resumed / "labels").glob("*.json")))
    assert 4 <= done_at_kill < count, "the kill should land mid-run"
    assert not (resumed / "labels.jsonl").exists()

    subprocess.run(render_cmd(resumed, count), check=True, capture_output=True, timeout=300)
    assert (resumed / "labels.jsonl").read_bytes() == (straight / "labels.jsonl").read_bytes()
    for sub in ("images", "masks"):
        names = sorted(p.name for p in (straight / sub).iterdir())
        assert names == sorted(p.name for p in (resumed / sub).iterdir())  # no stray temp files
        for name in names:
            a = np.asarray(Image.open(straight / sub / name), dtype=int)
            b = np.asarray(Image.open(resumed / sub / name), dtype=int)
            assert np.abs(a - b).max() <= (1 if sub == "images" else 0), f"{sub}/{name}"
