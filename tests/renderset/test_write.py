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

from sasmi.cli.main import main
from sasmi.images import read_gray

from conftest import REPO

PRESET = str(REPO / "scenes" / "muscle_paper.toml")


def render_cmd(out, count, *extra):
    return [sys.executable, "-m", "sasmi.cli.main", "render", PRESET, "--out", str(out), "--count", str(count),
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


# -- several writers on one folder ---------------------------------------------------------
# Runs `sasmi render` in a subprocess whose render_chip also appends "pid index" to LOG (one
# O_APPEND write per line), so the test sees which process rendered what; it sleeps a little
# per chip so that two processes started together overlap.
COUNTING = """
import os, sys, time
import sasmi.renderset.write as d
render_chip = d.render_chip
def counted(job, index, **kw):
    time.sleep(0.15)
    result = render_chip(job, index, **kw)
    with open(os.environ["LOG"], "a") as f:
        f.write(f"{os.getpid()} {index}\\n")
    return result
d.render_chip = counted
from sasmi.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def counted_cmd(out, count, *extra):
    return [sys.executable, "-c", COUNTING, *render_cmd(out, count, *extra)[3:]]


def renders_by_process(log):
    by_pid: dict[str, list[int]] = {}
    for line in log.read_text().splitlines():
        pid, index = line.split()
        by_pid.setdefault(pid, []).append(int(index))
    return by_pid


def assert_same_set(out, reference, count):
    assert (out / "labels.jsonl").read_bytes() == (reference / "labels.jsonl").read_bytes()
    for sub in ("images", "masks", "instances", "shadows"):
        names = sorted(p.name for p in (out / sub).iterdir())
        assert names == [f"{i:06d}.png" for i in range(count)], sub  # no stray temp files
        for name in names:
            a = np.asarray(Image.open(out / sub / name), dtype=int)
            b = np.asarray(Image.open(reference / sub / name), dtype=int)
            assert np.abs(a - b).max() <= (1 if sub == "images" else 0), f"{sub}/{name}"
    assert not (out / "claims").exists()


def test_two_processes_on_one_folder_render_each_chip_once(tmp_path, render_set):
    out, log = tmp_path / "shared", tmp_path / "log"
    env = {**os.environ, "LOG": str(log)}
    procs = [subprocess.Popen(counted_cmd(out, 8), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
             for _ in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err.decode()[-2000:]
    by_pid = renders_by_process(log)
    rendered = sorted(i for indices in by_pid.values() for i in indices)
    assert rendered == list(range(8)), f"each index exactly once, got {by_pid}"
    assert len(by_pid) == 2, f"both processes should have rendered some chips: {by_pid}"
    assert_same_set(out, render_set, 8)


def test_shards_make_the_whole_set(tmp_path, render_set, capsys):
    out = tmp_path / "sharded"
    assert main(["render", PRESET, "--out", str(out), "--count", "8", "--size", "32", "--spp", "4",
                 "--shard", "1/2"]) == 0
    assert sorted(p.name for p in (out / "labels").iterdir()) == [f"{i:06d}.json" for i in (1, 3, 5, 7)]
    assert not (out / "labels.jsonl").exists() and "4 chips of 8" in capsys.readouterr().out
    assert main(["render", PRESET, "--out", str(out), "--count", "8", "--size", "32", "--spp", "4",
                 "--shard", "0/2"]) == 0
    assert_same_set(out, render_set, 8)


@pytest.mark.parametrize("bad", ["2/2", "1", "-1/2", "a/b", "0/0"])
def test_bad_shard_is_refused(tmp_path, capsys, bad):
    assert main(["render", PRESET, "--out", str(tmp_path / "x"), "--shard", bad]) == 2
    assert "argument --shard" in capsys.readouterr().err and not (tmp_path / "x").exists()


def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_claims_of_live_processes_are_kept_and_of_dead_ones_taken(tmp_path, render_set, capsys):
    from sasmi.renderset.claims import HOST, _start_time

    out = tmp_path / "claimed"
    argv = ["render", PRESET, "--out", str(out), "--count", "8", "--size", "32", "--spp", "4"]
    assert main([*argv, "--shard", "7/8"]) == 0  # the set exists (run.json, chip 7)
    (out / "claims").mkdir(exist_ok=True)
    live = json.dumps({"host": HOST, "pid": os.getpid(), "started": _start_time(os.getpid())})
    (out / "claims" / "000002.claim").write_text(live)  # this test process: alive, holds chip 2
    (out / "claims" / "000005.claim").write_text(json.dumps({"host": HOST, "pid": dead_pid(), "started": None}))
    assert main(argv) == 0
    labels = sorted(p.name for p in (out / "labels").iterdir())
    assert labels == [f"{i:06d}.json" for i in range(8) if i != 2], "chip 2 is held, chip 5's holder is dead"
    assert not (out / "labels.jsonl").exists() and "1 chips of 8" in capsys.readouterr().out
    (out / "claims" / "000002.claim").unlink()  # its holder gave up
    assert main(argv) == 0
    assert_same_set(out, render_set, 8)


def test_claims_across_hosts_go_by_age(tmp_path):
    from sasmi.renderset.claims import Claims

    mine, other = Claims(tmp_path, stale_after=60), Claims(tmp_path, stale_after=60)
    assert mine.take("a") and not other.take("a")  # one process holds it, a second one (alive) cannot
    mine.release("a")
    assert other.take("a")
    away = tmp_path / "b.claim"
    away.write_text(json.dumps({"host": "elsewhere", "pid": 1, "started": None}))
    assert not mine.take("b"), "a fresh claim of another host is kept"
    os.utime(away, (time.time() - 120, time.time() - 120))
    assert mine.take("b"), "an old one is stale"
    assert json.loads(away.read_text())["pid"] == os.getpid()


def test_a_claim_never_shows_empty(tmp_path):
    # a holder killed between creating its claim and writing it would leave an empty claim, which
    # counts as alive for a minute: a rerun would skip the chip and never assemble labels.jsonl.
    # A write that fails stands in for the kill
    from sasmi.renderset.claims import Claims

    dying, rerun = Claims(tmp_path), Claims(tmp_path)
    dying._me = None  # writing the holder's record fails
    with pytest.raises(TypeError):
        dying.take("a")
    assert list(tmp_path.iterdir()) == []  # no claim, empty or not, and no draft
    assert rerun.take("a") and json.loads((tmp_path / "a.claim").read_text())["pid"] == os.getpid()


def test_a_rerun_after_an_early_failure_may_change_settings(tmp_path, capsys):
    out = tmp_path / "early"
    out.mkdir()
    (out / "run.json").write_text(json.dumps({"seed": 5, "size": 64}))  # a run that died before its first chip
    assert main(["render", PRESET, "--out", str(out), "--count", "1", "--size", "32", "--spp", "4"]) == 0
    assert json.loads((out / "run.json").read_text())["size"] == 32
    assert main(["render", PRESET, "--out", str(out), "--count", "1", "--size", "32", "--spp", "4"]) == 0
    assert main(["render", PRESET, "--out", str(out), "--count", "2", "--size", "32", "--spp", "4"]) == 0
    assert json.loads((out / "run.json").read_text())["count"] == 2


def test_held_claims_are_kept_alive_for_other_hosts(tmp_path, monkeypatch):
    import sasmi.renderset.claims
    from sasmi.renderset.claims import Claims

    holder = Claims(tmp_path, stale_after=0.5)
    assert holder.take("shard-000000")
    monkeypatch.setattr(sasmi.renderset.claims, "HOST", "another-host")  # what a process elsewhere sees
    other = Claims(tmp_path, stale_after=0.5)
    with holder.kept_alive(every=0.1):
        time.sleep(1.0)
        assert not other.take("shard-000000"), "a claim touched meanwhile is alive"
    time.sleep(0.7)
    assert other.take("shard-000000"), "untouched for longer than stale_after: its holder is gone"


def test_a_transform_runs_in_one_process_only(tmp_path):
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import load_preset

    preset = load_preset(REPO / "scenes" / "muscle_paper.toml")
    for job in (RenderJob(preset=preset, out=tmp_path / "a", count=2, size=32, workers=2),
                RenderJob(preset=preset, out=tmp_path / "b", count=2, size=32, scheduler="tcp://127.0.0.1:1")):
        with pytest.raises(ValueError, match="one worker"):
            render_set(job, transform=lambda images, masks, indices: images)
        assert not job.out.exists()
