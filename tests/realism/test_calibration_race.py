"""`sasmi calibrate --searches N`: the searches race over the first half of the budget, by time or by trials, and the
lowest then continues alone; the report and the calibrated trial are the leader's."""
from __future__ import annotations

import re

import optuna
import pytest

from sasmi.realism.calibrate import CalibrateConfig, calibrate
from sasmi.realism.calibration_study import leader, next_search, study_name
from sasmi.scene.preset import load_preset

GAIN = optuna.distributions.FloatDistribution(0.01, 3.0)


def studies_with(values: list[list[float]], seconds: list[float]) -> list:
    """In-memory studies holding trials of these objectives and that much search time each."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    studies = []
    for told, spent in zip(values, seconds):
        study = optuna.create_study(direction="minimize")
        for v in told:
            study.add_trial(optuna.trial.create_trial(params={"post.gain": 0.5}, distributions={"post.gain": GAIN},
                                                      value=v))
        study.set_user_attr("seconds", spent)
        studies.append(study)
    return studies


def test_each_search_runs_its_share_of_the_first_half_then_the_lowest_alone():
    cfg = CalibrateConfig(minutes=1.0, searches=2)  # 60 s: 15 s each to race, then 30 s for the leader
    assert next_search(studies_with([[3.0], []], [2.0, 0.0]), cfg) == 1  # fewest trials first
    assert next_search(studies_with([[3.0], [2.0, 2.5]], [2.0, 4.0]), cfg) == 0
    assert next_search(studies_with([[3.0] * 5, [2.0]], [15.0, 2.0]), cfg) == 1  # search 0 ran its share
    for seconds in ([15.0, 15.0], [15.0, 44.0], [29.0, 30.0]):  # race over: the lower best continues
        assert next_search(studies_with([[3.0, 1.5], [2.0, 2.5]], seconds), cfg) == 0
        assert next_search(studies_with([[3.0, 2.1], [2.0, 2.5]], seconds), cfg) == 1
    assert next_search(studies_with([[3.0], [2.0]], [16.0, 44.0]), cfg) is None  # 60 s spent
    one = CalibrateConfig(minutes=1.0, searches=1)
    assert next_search(studies_with([[3.0] * 9], [59.0]), one) == 0
    assert next_search(studies_with([[3.0] * 9], [60.0]), one) is None


def test_with_a_trial_budget_each_search_races_a_quarter_of_the_trials_of_two():
    cfg = CalibrateConfig(trials=10, searches=2)  # ceil(10 / 4) = 3 trials each to race
    assert next_search(studies_with([[3.0] * 2, [2.0] * 3], [1.0, 1.0]), cfg) == 0
    assert next_search(studies_with([[3.0] * 3, [2.0] * 3], [1.0, 1.0]), cfg) == 1  # the leader
    assert next_search(studies_with([[1.0] * 3, [2.0] * 6], [1.0, 1.0]), cfg) == 0  # a lower best leads
    assert next_search(studies_with([[3.0] * 3, [2.0] * 7], [1.0, 1.0]), cfg) is None
    three = CalibrateConfig(trials=12, searches=3)  # 2 each
    assert next_search(studies_with([[3.0] * 2, [2.0] * 2, [4.0]], [1.0, 1.0, 1.0]), three) == 2
    assert leader(studies_with([[3.0], [], [2.5]], [1.0, 0.0, 1.0])) == 2  # a search with no trial told is last


def test_the_report_and_the_calibrated_preset_are_the_leaders(real_chips, tmp_path, monkeypatch):
    """Three searches over the gain, scored by its distance from 0.4 alone (no render per trial): the one whose race
    came closest continues, its trials fill the rest of the budget, and its trial is the calibrated preset."""
    import sasmi.realism.calibrate as calibrate_module

    def distance_from_04(raw, *args):
        return {"objective": 0.01 + abs(load_gain(raw) - 0.4), "statistics": 0.0, "distribution": 0.0, "phi_ratio": 1.0,
                "recall": 0.5, "passed": 0}

    monkeypatch.setattr(calibrate_module, "trial_score", distance_from_04)
    cfg = CalibrateConfig(params=("post.gain",), trials=24, chips=8, size=32, final_chips=8, searches=3,
                          contenders=2, profile_trials=0)
    out = calibrate(real_chips / "targets", "muscle_paper", cfg, tmp_path / "run", progress=False)
    storage = f"sqlite:///{out / 'study.db'}"
    studies = [optuna.load_study(study_name=study_name(i), storage=storage) for i in range(3)]
    raced = [min(t.value for t in s.trials[:4]) for s in studies]  # ceil(24 / 6) = 4 trials each
    chosen = raced.index(min(raced))
    assert len({round(v, 6) for v in raced}) == 3  # three paths, not one asked thrice
    assert sorted(len(s.trials) for s in studies) == [4, 4, 16] and len(studies[chosen].trials) == 16
    report = (out / "report.md").read_text()
    assert re.search(rf"search {chosen}, the lowest when the race ended, continued alone", report), report[:600]
    calibrated = studies[chosen].trials[studies[chosen].user_attrs["calibrated_trial"]]
    assert load_gain(load_preset(out / "preset.toml").raw) == pytest.approx(calibrated.params["post.gain"], rel=1e-3)
    assert "calibrated_trial" not in studies[(chosen + 1) % 3].user_attrs


def load_gain(raw: dict) -> float:
    gain = raw["post"]["gain"]
    return sum(gain["uniform"]) / 2 if isinstance(gain, dict) else float(gain)
