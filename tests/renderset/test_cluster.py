"""`sasmi render --scheduler`: a real `dask scheduler` and two `dask worker` processes on localhost."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from sasmi.cli.main import main

from conftest import REPO

PRESET = str(REPO / "scenes" / "muscle_paper.toml")
DASK = Path(sys.executable).parent / "dask"
START_TIMEOUT_S = 120


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """tcp://127.0.0.1:PORT of a scheduler with two single-threaded workers that import this checkout."""
    from distributed import Client

    logs = tmp_path_factory.mktemp("dask")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    address = f"tcp://127.0.0.1:{free_port()}"
    commands = [[str(DASK), "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                 "--no-dashboard"]]
    commands += [[str(DASK), "worker", address, "--nthreads", "1", "--no-dashboard", "--no-nanny",
                  "--host", "127.0.0.1", "--name", f"w{k}"] for k in range(2)]
    procs = []
    try:
        for k, command in enumerate(commands):
            log = open(logs / f"{k}.log", "w")
            procs.append(subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT,
                                          start_new_session=True))
        with Client(address, timeout=START_TIMEOUT_S) as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT_S)
        yield address
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=30)


def test_cluster_renders_the_same_chips_and_resumes(tmp_path, scheduler, render_set):
    out = tmp_path / "cluster"
    argv = ["render", PRESET, "--out", str(out), "--count", "6", "--size", "32", "--spp", "4",
            "--scheduler", scheduler]
    assert main(argv) == 0
    reference = (render_set / "labels.jsonl").read_text().splitlines()[:6]
    assert (out / "labels.jsonl").read_text().splitlines() == reference
    for i in range(6):
        name = f"{i:06d}.png"
        for sub in ("images", "masks", "instances", "shadows"):
            a = np.asarray(Image.open(out / sub / name), dtype=int)
            b = np.asarray(Image.open(render_set / sub / name), dtype=int)
            assert np.abs(a - b).max() <= (1 if sub == "images" else 0), f"{sub}/{name}"

    # resumable: only the incomplete chips are rendered again
    kept = {i: (out / "images" / f"{i:06d}.png").stat().st_mtime_ns for i in (0, 2, 3, 5)}
    for i in (1, 4):
        (out / "labels" / f"{i:06d}.json").unlink()
    (out / "labels.jsonl").unlink()
    time.sleep(0.01)
    assert main(argv) == 0
    assert {i: (out / "images" / f"{i:06d}.png").stat().st_mtime_ns for i in kept} == kept
    assert (out / "labels.jsonl").read_text().splitlines() == reference


def test_wds_shards_on_the_cluster(tmp_path, scheduler):
    from sasmi.renderset.shards import shard_files

    local, remote = tmp_path / "local", tmp_path / "remote"
    common = [PRESET, "--count", "5", "--size", "32", "--spp", "4", "--format", "wds", "--per-shard", "2"]
    assert main(["render", *common, "--out", str(local)]) == 0
    assert main(["render", *common, "--out", str(remote), "--scheduler", scheduler]) == 0
    from test_shards import assert_same_samples, members

    assert [p.name for p in shard_files(remote)] == [p.name for p in shard_files(local)] == \
        ["shard-000000.tar", "shard-000001.tar", "shard-000002.tar"]
    for a, b in zip(shard_files(remote), shard_files(local)):
        assert_same_samples(members(a), members(b))


def test_unreachable_scheduler_is_one_line(tmp_path, capsys, monkeypatch):
    import sasmi.renderset.cluster

    monkeypatch.setattr(sasmi.renderset.cluster, "CONNECT_TIMEOUT_S", 2)
    assert main(["render", PRESET, "--out", str(tmp_path / "x"), "--count", "1", "--size", "32", "--spp", "4",
                 "--scheduler", f"tcp://127.0.0.1:{free_port()}"]) == 2
    assert "--scheduler tcp://127.0.0.1:" in capsys.readouterr().err


def test_a_failing_chip_on_a_worker_is_one_error_and_frees_the_claims(tmp_path, scheduler, capsys):
    out = tmp_path / "failing"
    argv = ["render", PRESET, "--out", str(out), "--size", "32", "--spp", "4", "--scheduler", scheduler]
    assert main([*argv, "--count", "1"]) == 0
    (out / "labels" / "000003.json").mkdir()  # the worker cannot write chip 3's labels
    assert main([*argv, "--count", "6"]) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("sasmi render:")]
    assert len(errors) == 1 and "000003.json: cannot write" in errors[0] and "Traceback" not in err, err
    assert not list((out / "claims").glob("*.claim"))
    (out / "labels" / "000003.json").rmdir()
    assert main([*argv, "--count", "6"]) == 0
    assert len((out / "labels.jsonl").read_text().splitlines()) == 6 and not (out / "claims").exists()


@pytest.mark.parametrize("extra, flag", [(["--scheduler", "8786"], "argument --scheduler"),
                                         (["--scheduler", "http://x:1"], "argument --scheduler"),
                                         (["--scheduler", "tcp://127.0.0.1:1", "--workers", "2"], "--scheduler and --workers")])
def test_bad_scheduler_flags(tmp_path, capsys, extra, flag):
    assert main(["render", PRESET, "--out", str(tmp_path / "x"), "--count", "1", *extra]) == 2
    assert flag in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_scheduler_addresses_accepted():
    from sasmi.cli.render import scheduler_address

    for text in ("tcp://127.0.0.1:8786", "tcp://[::1]:8786", "tls://node-3.cluster:8786", "node3:8786"):
        assert scheduler_address(text) == text


def test_tasks_in_flight_keep_every_worker_busy_while_the_caller_is(scheduler):
    """A few tasks per worker thread stay submitted while the caller holds a result, and every item runs once."""
    from distributed import Client

    from sasmi.renderset.cluster import TASKS_PER_THREAD, stream

    with Client(scheduler, timeout=START_TIMEOUT_S) as client:
        granted = []
        results = stream(client, lambda job, item, threads: (job, item * 2), "job", list(range(30)),
                         lambda i: granted.append(i) is None, None)
        first = next(results)
        assert len(granted) == TASKS_PER_THREAD * 2  # two single-threaded workers
        done = sorted([first, *results])
        assert done == [(i, ("job", 2 * i)) for i in range(30)] and sorted(granted) == list(range(30))
