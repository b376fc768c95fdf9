"""benchmarks/preset_floors.py and benchmarks/atr_paired.py: a preset's own floors as ATR negatives, and two
atr-bench runs compared seed by seed."""
from __future__ import annotations

import json

import numpy as np
import pytest

from sasmi.scene.preset import load_preset

from conftest import benchmark


def test_the_floors_keep_sonar_seabed_and_gray_levels_and_draw_no_object(tmp_path):
    floors = benchmark("preset_floors")
    out = tmp_path / "floors.toml"
    assert floors.main(["cylinder_chip", "--out", str(out)]) == 0
    source, written = load_preset("cylinder_chip"), load_preset(out)
    for section in ("sonar", "seafloor", "post"):
        assert written.raw[section] == source.raw[section]
    assert source.sample(0, 0).targets and source.raw.get("companions")  # the start draws objects...
    assert all(not written.sample(0, i).targets for i in range(20))  # ...its floors none


def test_floors_of_a_missing_preset_are_one_line_and_nothing_written(tmp_path, capsys):
    out = tmp_path / "floors.toml"
    assert benchmark("preset_floors").main(["nonesuch", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("preset_floors: error: nonesuch:") and err.count("\n") == 1
    assert not out.exists()


def _bench(folder, auc_by_seed: dict, pd: float = 0.5) -> None:
    folder.mkdir()
    rows = [{"settings": {}, "inputs": {}}]
    for (n, way), values in auc_by_seed.items():
        rows += [{"n": n, "way": way, "seed": s, "accuracy": 0.5, "auc": v, "pd": pd} for s, v in enumerate(values)]
    (folder / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))


def test_two_runs_are_paired_seed_by_seed(tmp_path):
    paired = benchmark("atr_paired")
    real = [0.8, 0.9, 0.7]
    _bench(tmp_path / "a", {("10", "real"): real, ("0", "alone"): [0.6, 0.9, 0.7]})
    # the second run: `real` the same, `alone` 0.1 better seed by seed, and one seed more, unpaired
    _bench(tmp_path / "b", {("10", "real"): real, ("0", "alone"): [0.7, 1.0, 0.8, 0.1]}, pd=0.75)
    rows = {(r["n"], r["way"]): r for r in paired.paired(paired.runs(tmp_path / "a"), paired.runs(tmp_path / "b"))}
    assert rows[("10", "real")]["d_auc"] == pytest.approx((0.0, 0.0, 0.0))
    alone = rows[("0", "alone")]
    assert alone["seeds"] == 3 and alone["auc_second"] == pytest.approx(np.mean([0.7, 1.0, 0.8]))
    assert alone["d_auc"] == pytest.approx((0.1, 0.1, 0.1))  # the same gain at every seed: no spread
    assert alone["d_pd"] == pytest.approx((0.25, 0.25, 0.25))


def test_the_interval_is_students_t_over_the_seeds():
    mean, low, high = benchmark("atr_paired")._mean_and_interval([0.0, 0.1, 0.2])
    assert mean == pytest.approx(0.1) and high - mean == pytest.approx(4.303 * 0.1 / np.sqrt(3), rel=1e-3)
    assert mean - low == pytest.approx(high - mean)


def test_runs_that_share_no_arm_are_one_line_and_exit_2(tmp_path, capsys):
    _bench(tmp_path / "a", {("10", "real"): [0.8, 0.9]})
    _bench(tmp_path / "b", {("40", "real"): [0.8, 0.9]})
    assert benchmark("atr_paired").main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2
    assert "share no arm" in capsys.readouterr().err
