"""`sasmi calibrate`'s search: --step sets CMA-ES's first step; with --searches N the searches share the budget, by
time or by trials, each over its own scenes, and the one whose report renders the two-sample test tells least is
calibrated; with --redraw-scenes each CMA-ES generation renders its own draw of the scenes; a study begun before these
flags continues as one search at Optuna's own step, every trial on the same scenes, and searches that raced over one
draw are refused."""
from __future__ import annotations

import json
import re

import numpy as np
import optuna
import pytest

from sasmi.realism.calibrate import CalibrateConfig, calibrate, render_chips
from sasmi.errors import SasmiError
from sasmi.realism.calibration_report import search_lines
from sasmi.realism.calibration_study import next_search, sampler_for, study_name
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


def test_each_search_runs_its_share_of_the_budget_the_one_furthest_behind_first():
    cfg = CalibrateConfig(minutes=1.0, searches=2)  # 60 s: 30 s each
    assert next_search(studies_with([[3.0], []], [2.0, 0.0]), cfg) == 1  # the least time first
    assert next_search(studies_with([[3.0], [2.0, 2.5]], [2.0, 4.0]), cfg) == 0
    assert next_search(studies_with([[3.0] * 5, [2.0]], [30.0, 2.0]), cfg) == 1  # search 0 ran its share
    assert next_search(studies_with([[1.0] * 5, [2.0]], [29.0, 30.0]), cfg) == 0  # its best does not matter
    assert next_search(studies_with([[3.0], [2.0]], [30.0, 30.0]), cfg) is None  # 60 s spent
    one = CalibrateConfig(minutes=1.0, searches=1)
    assert next_search(studies_with([[3.0] * 9], [59.0]), one) == 0
    assert next_search(studies_with([[3.0] * 9], [60.0]), one) is None


def test_with_a_trial_budget_each_search_asks_its_share_of_the_trials():
    cfg = CalibrateConfig(trials=10, searches=2)  # 5 each
    assert next_search(studies_with([[3.0] * 2, [2.0] * 3], [9.0, 1.0]), cfg) == 0  # the fewest trials first
    assert next_search(studies_with([[3.0] * 5, [2.0] * 3], [1.0, 9.0]), cfg) == 1
    assert next_search(studies_with([[3.0] * 5, [2.0] * 5], [1.0, 1.0]), cfg) is None
    odd = CalibrateConfig(trials=5, searches=2)  # 3 and 2
    assert next_search(studies_with([[3.0] * 3, [2.0]], [1.0, 1.0]), odd) == 1
    assert next_search(studies_with([[3.0] * 3, [2.0] * 2], [1.0, 1.0]), odd) is None
    three = CalibrateConfig(trials=12, searches=3)  # 4 each
    assert next_search(studies_with([[3.0] * 4, [2.0] * 3, [4.0] * 3], [1.0, 1.0, 1.0]), three) == 1


def test_the_report_says_when_another_search_was_told_apart_within_the_tests_spread():
    studies = studies_with([[1.4], [1.6], [1.5]], [60.0, 60.0, 60.0])
    for study, elsewhere in zip(studies, (1.7, 3.6, 1.9)):  # trial 0 calibrated: its score on other draws
        study.set_user_attr("contenders", {"draws": 4, "scores": [[0, study.best_value, elsewhere]]})

    def judged(*told: tuple[float, float]) -> list[tuple[int, dict]]:
        return [(0, {"two_sample": auc, "two_sample_std": std, "phi_ratio": 1.1, "passed": 12}) for auc, std in told]

    apart = "\n".join(search_lines(studies, 0, judged((0.80, 0.03), (0.90, 0.04), (0.86, 0.05))))
    assert "| 0 (kept) | 1 | 1.0 | 1.4 | 0 | 1.7 | 0.800 ± 0.030 |" in apart
    assert "| 1 | 1 | 1.0 | 1.6 | 0 | 3.6 | 0.900 ± 0.040 |" in apart
    assert "close choice" not in apart  # 0.10 and 0.06 apart, beyond either's spread
    close = "\n".join(search_lines(studies, 0, judged((0.80, 0.03), (0.84, 0.05), (0.83, 0.02))))
    assert "Searches 1, 2 were told apart within the test's spread over folds of search 0's" in close
    one = "\n".join(search_lines(studies, 1, judged((0.84, 0.02), (0.82, 0.03), (0.95, 0.02))))
    assert "Search 0 was told apart within the test's spread over folds of search 1's" in one


def test_each_search_renders_its_own_scenes_the_one_told_least_is_kept_the_others_written_beside(real_chips, tmp_path,
                                                                                                  monkeypatch):
    """Three searches over the gain, scored by its distance from a gain their scenes ask for alone (no render per
    trial): 0.4, 0.8 and 1.6 on the scenes of searches 0, 1 and 2, the last two scoring higher all along. The report's
    two-sample test here tells brighter renders less often: search 2, whose gain is highest, is kept whatever its
    objective, its trial is the calibrated preset and its knobs are judged on its own scenes; the other two searches'
    calibrated presets are written beside it."""
    import sasmi.realism.calibrate as calibrate_module
    import sasmi.realism.calibration_objective as objective_module

    seeds = []

    def distance_from_its_scenes_gain(raw, preset_path, real, cfg, *args):
        seeds.append(cfg.seed)
        search = cfg.seed // 1000  # the other draws (seeds 2-9) ask for search 0's gain
        return {"objective": 0.01 + 0.5 * search + abs(load_gain(raw) - (0.4, 0.8, 1.6)[search]),
                "statistics": 0.0, "distribution": 0.0, "phi_ratio": 1.0, "recall": 0.5, "passed": 0}

    monkeypatch.setattr(calibrate_module, "trial_score", distance_from_its_scenes_gain)
    monkeypatch.setattr(objective_module, "told_apart",
                        lambda real, images, seed: {"auc": 1.0 - float(images.mean()), "auc_std": 0.0})
    cfg = CalibrateConfig(params=("post.gain",), trials=24, chips=8, size=32, final_chips=8, searches=3,
                          contenders=2, profile_trials=0)
    out = calibrate(real_chips / "targets", "muscle_paper", cfg, tmp_path / "run", progress=False)
    assert seeds[:3] == [0, 1000, 2000] and set(seeds) == {0, 1000, 2000, *range(2, 10)}  # then the other draws
    storage = f"sqlite:///{out / 'study.db'}"
    studies = [optuna.load_study(study_name=study_name(i), storage=storage) for i in range(3)]
    assert [len(s.trials) for s in studies] == [8, 8, 8]
    gains = [s.trials[s.user_attrs["calibrated_trial"]].params["post.gain"] for s in studies]
    assert gains[0] < gains[1] < gains[2] and min(s.best_value for s in studies) == studies[0].best_value
    assert load_gain(load_preset(out / "preset.toml").raw) == pytest.approx(gains[2], rel=1e-3)
    for i in (0, 1):  # the searches not kept: their calibrated presets beside the kept one, loadable
        assert load_gain(load_preset(out / f"search-{i}.toml").raw) == pytest.approx(gains[i], rel=1e-3)
    assert not (out / "search-2.toml").exists()
    assert set(seeds[24:]) - set(range(2, 10)) == {2000}  # the kept search's knobs judged on its own scenes
    report = (out / "report.md").read_text()
    assert re.search(r"is kept: search 2\.", report) and "| 2 (kept) | 8 |" in report, report[:1500]
    assert report.count("(kept)") == 1 and "`search-0.toml`, `search-1.toml`" in report


def load_gain(raw: dict) -> float:
    gain = raw["post"]["gain"]
    return sum(gain["uniform"]) / 2 if isinstance(gain, dict) else float(gain)


def first_generation(step: float | None) -> np.ndarray:
    """How far the 6 trials after the start (trial 0) lie from it, knob by knob, in fractions of each knob's range."""
    cfg = CalibrateConfig(params=("post.gain", "post.tvg_strength"), step=step)
    x0 = {"post.gain": 0.5, "post.tvg_strength": 0.5}
    study = optuna.create_study(direction="minimize", sampler=sampler_for(cfg, x0, 0))
    study.enqueue_trial(x0)
    moves = []
    for number in range(7):  # CMA-ES draws 6 a generation over 2 knobs
        study.sampler = sampler_for(cfg, x0, number)
        trial = study.ask()
        gain = trial.suggest_float("post.gain", 0.03, 2.0, log=True)
        tvg = trial.suggest_float("post.tvg_strength", 0.0, 1.0)
        study.tell(trial, 1.0)
        moves.append([np.log(gain / 0.5) / np.log(2.0 / 0.03), tvg - 0.5])
    return np.array(moves[1:])


def test_the_first_generation_lies_a_step_from_the_start():
    """The same draws of the same seed, at 0.05 of each knob's range in place of Optuna's 1/6: 0.3 x as far."""
    default, small = first_generation(None), first_generation(0.05)
    assert 0.05 < np.sqrt(np.mean(default ** 2)) < 0.5
    np.testing.assert_allclose(small, 0.3 * default, atol=0.005)


def test_a_study_begun_before_the_flags_continues_as_one_search_at_optunas_step(real_chips, tmp_path, monkeypatch,
                                                                                quick_two_sample):
    import sasmi.realism.calibrate as calibrate_module

    monkeypatch.setattr(calibrate_module, "trial_score", lambda raw, *args: {
        "objective": 0.01 + abs(load_gain(raw) - 0.4), "statistics": 0.0, "distribution": 0.0, "phi_ratio": 1.0,
        "recall": 0.5, "passed": 0})
    cfg = CalibrateConfig(params=("post.gain",), trials=4, chips=8, size=32, final_chips=8, contenders=1,
                          profile_trials=0)
    out = calibrate(real_chips / "targets", "muscle_paper", cfg, tmp_path / "run", progress=False)
    record = json.loads((out / "calibrate.json").read_text())
    for key in ("step", "searches", "redraw_scenes", "search_scenes"):
        del record["identity"][key]
    (out / "calibrate.json").write_text(json.dumps(record))
    raced = {**record, "identity": {**record["identity"], "searches": 2}}
    (tmp_path / "raced").mkdir()
    (tmp_path / "raced" / "calibrate.json").write_text(json.dumps(raced))
    with pytest.raises(SasmiError, match="other settings \\(search_scenes\\)"):
        calibrate(real_chips / "targets", "muscle_paper", CalibrateConfig(**{**cfg.__dict__, "searches": 2}),
                  tmp_path / "raced", progress=False)
    for changed, named in (({"searches": 2}, "searches"), ({"step": 0.05}, "step"),
                           ({"redraw_scenes": True}, "redraw_scenes")):
        with pytest.raises(SasmiError, match=f"other settings \\({named}\\)"):
            calibrate(real_chips / "targets", "muscle_paper", CalibrateConfig(**{**cfg.__dict__, **changed}), out,
                      progress=False)
    calibrate(real_chips / "targets", "muscle_paper", CalibrateConfig(**{**cfg.__dict__, "trials": 6}), out,
              progress=False)
    assert len(optuna.load_study(study_name="calibrate", storage=f"sqlite:///{out / 'study.db'}").trials) == 6
    with pytest.raises(SasmiError, match="--step: 0.6"):
        CalibrateConfig(step=0.6).validate()


def firsts_asked(real_chips, out, monkeypatch, **flags) -> list[tuple[int, int, int | None]]:
    """(trial number, first scene it rendered, its CMA-ES generation) of a 20-trial search over two knobs."""
    import sasmi.realism.calibrate as calibrate_module

    firsts = []

    def records_its_scenes(raw, preset_path, real, cfg, encoder, first):
        firsts.append(first)
        return {"objective": 0.01 + abs(load_gain(raw) - 0.4), "statistics": 0.0, "distribution": 0.0,
                "phi_ratio": 1.0, "recall": 0.5, "passed": 0}

    monkeypatch.setattr(calibrate_module, "trial_score", records_its_scenes)
    cfg = CalibrateConfig(params=("post.gain", "post.tvg_strength"), trials=20, chips=8, size=32, final_chips=8,
                          contenders=1, profile_trials=0, **flags)
    calibrate(real_chips / "targets", "muscle_paper", cfg, out, progress=False)
    trials = optuna.load_study(study_name="calibrate", storage=f"sqlite:///{out / 'study.db'}").trials
    return [(t.number, first, t.system_attrs.get("cma:generation")) for t, first in zip(trials, firsts)]


def test_with_redraw_scenes_each_generation_renders_its_own_draw(real_chips, tmp_path, monkeypatch, quick_two_sample):
    """CMA-ES asks 6 a generation over two knobs: the start renders scenes 0-7, generation g scenes 8(g + 1), ...;
    without the flag every trial renders scenes 0-7."""
    redrawn = firsts_asked(real_chips, tmp_path / "redrawn", monkeypatch, redraw_scenes=True)
    assert [first for _, first, _ in redrawn] == [0] + [8] * 6 + [16] * 6 + [24] * 6 + [32]
    assert all(first == 8 * (generation + 1) for _, first, generation in redrawn[1:])
    assert "each generation on its own draw of the scenes" in (tmp_path / "redrawn" / "report.md").read_text()
    same = firsts_asked(real_chips, tmp_path / "same", monkeypatch)
    assert [first for _, first, _ in same] == [0] * 20


def test_a_trials_scenes_from_its_first_are_those_of_a_longer_draw():
    preset = load_preset("cylinder_chip")
    cfg = CalibrateConfig(size=32, spp=1)
    np.testing.assert_array_equal(render_chips(preset, 3, cfg, 4, first=3), render_chips(preset, 6, cfg, 4)[3:])
    assert not np.array_equal(render_chips(preset, 3, cfg, 4, first=3), render_chips(preset, 3, cfg, 4))
    with pytest.raises(SasmiError, match="--redraw-scenes: .*--sampler cmaes"):
        CalibrateConfig(redraw_scenes=True, sampler="tpe").validate()
