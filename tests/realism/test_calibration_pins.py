"""What `sasmi calibrate`'s report says each knob, and each pair of knobs that move together, is pinned by: moved
alone, then rivals held 15 % away (the search's trials and a profile) scored on other draws, on objectives whose
ridges and noise are known."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sasmi.realism.calibration_pins import (RISE, moves_with, pairs, profile, ridge, sensitivity, together,
                                            trade_offs)
from sasmi.realism.calibration_report import ridges_figure, sensitivity_lines, together_lines
from sasmi.realism.preset_space import knob


def _on_draws(objective, shift=lambda seed: 0.0):
    """objectives_of(settings, seed): `objective` of each setting, plus what the draw of `seed` adds to all."""
    return lambda settings, seed=0: [objective(v) + shift(seed) for v in settings]


def test_the_report_tells_a_pinned_knob_from_one_the_chips_cannot_pin():

    calls = []

    def objectives(settings, seed=0):  # sees the gain alone: every noise level scores alike
        calls.append(settings)
        return [1.0 + 20 * math.log(values["post.gain"] / 0.3) ** 2 for values in settings]

    best = {"post.gain": 0.3, "post.noise_std": 0.05}
    pins = sensitivity(best, objectives)
    assert len(calls) == 1 and len(calls[0]) == 5  # one batch for the trials' workers ...
    assert calls[0][0] == best  # ... the calibrated setting, then each knob alone down and up
    assert pins["post.gain"]["alone"] and pins["post.gain"]["rise"] > 0.5
    assert pins["post.gain"]["moved"][0] < 0.3 < pins["post.gain"]["moved"][1]
    assert not pins["post.noise_std"]["alone"] and pins["post.noise_std"]["rise"] == 0.0
    assert pins["post.noise_std"]["moved"] == [pytest.approx(0.03), pytest.approx(0.07)]  # 20 % of its 0-0.1 range
    trials = [(1.0 + 20 * math.log(g / 0.3) ** 2, {"post.gain": g, "post.noise_std": n})
              for g, n in zip(np.linspace(0.2, 0.4, 21), np.linspace(0.0, 0.1, 21))]
    pins = trade_offs(pins, trials, best, objectives, [2, 3])
    gain = pins["post.gain"]
    assert gain["pinned"] is True and pins["post.noise_std"]["pinned"] is False
    # the nearest trials beyond 15 %, the best of each side, scored again: 20 x log(0.25 / 0.3)² = +66 %
    assert gain["beyond"]["below"]["value"] == pytest.approx(0.25) and gain["beyond"]["below"]["rise"] > 0.6
    assert gain["beyond"]["above"]["value"] == pytest.approx(0.35) and gain["fresh"] == [1.0, 1.0]
    # the calibrated setting and gain's two, on each of the two draws: a knob the chips cannot pin alone is not
    assert len(calls) == 3 and [len(c) for c in calls[1:]] == [3, 3] and calls[1][0] == best
    lines = "\n".join(sensitivity_lines(pins, best))
    assert "cannot pin, any value scoring alike: post.noise_std." in lines and "| 0.25: +66% ± 0% |" in lines


def test_knobs_that_trade_along_a_ridge_are_not_called_pinned():
    """Gain and albedo each move the objective alone, but only their product is seen: the best trials the search
    found along the ridge beyond 15 % score as well on other draws; the looks, seen alone, stay pinned."""

    def objective(v):
        seen = v["post.gain"] * v["seafloor.albedo"]
        return 1.0 + 4 * math.log(seen / 0.1) ** 2 + math.log(v["post.speckle_looks"] / 5) ** 2

    best = {"post.gain": 0.25, "seafloor.albedo": 0.4, "post.speckle_looks": 5.0}
    pins = sensitivity(best, _on_draws(objective))
    assert all(p["alone"] for p in pins.values())
    rng = np.random.default_rng(0)
    gains = np.exp(rng.uniform(math.log(0.15), math.log(0.45), 60))  # the search's samples along the ridge
    trials = [(objective(v), v) for v in ({"post.gain": g, "seafloor.albedo": 0.1 / g * math.exp(rng.normal(0, 0.03)),
                                           "post.speckle_looks": 5.0 * math.exp(rng.normal(0, 0.03))} for g in gains)]
    trials += [(objective(v), v) for v in ({**best, "post.speckle_looks": looks} for looks in (2.0, 3.0, 8.0, 12.0))]
    # the other draws add the same to every setting: the comparison is paired, so a noisy draw hides nothing
    traded = trade_offs(pins, [(objective(best), best), *trials], best, _on_draws(objective, lambda s: 0.3 * s),
                        [1, 2, 3, 4])
    assert traded["post.gain"]["pinned"] is False and traded["seafloor.albedo"]["pinned"] is False
    assert traded["post.gain"]["beyond"]["above"]["rise"] < 0.05
    # the rival beyond +15 % held gain there with albedo lower, the looks nearly where they were
    assert [n for n, _ in traded["post.gain"]["beyond"]["above"]["moved_too"]] == ["seafloor.albedo",
                                                                                    "post.speckle_looks"]
    assert traded["post.speckle_looks"]["pinned"] is True
    assert [traded["post.speckle_looks"]["beyond"][s]["value"] for s in ("below", "above")] == [3.0, 8.0]
    lines = "\n".join(sensitivity_lines(traded, best))
    assert "the spread over scene draws hides them): post.gain, seafloor.albedo." in lines
    # what they trade with: each other, falling as the other rises
    assert [m for m, _ in traded["post.gain"]["moves_with"]] == ["seafloor.albedo"]
    assert traded["post.gain"]["moves_with"][0][1] < -0.9 and traded["post.speckle_looks"]["moves_with"] == []
    assert "| **no** | seafloor.albedo (-1.00) |" in lines
    few = trade_offs(pins, [(objective(best), best)], best, _on_draws(objective), [1])  # a search too short
    assert {p["pinned"] for p in few.values()} == {None}
    assert "| cannot tell |" in "\n".join(sensitivity_lines(few, best))


def test_a_value_that_scored_as_well_on_the_search_scenes_alone_does_not_unpin_a_knob():
    """The search's scenes flattered looks of 6.5 (0.62 against the best's 0.6): on other draws it scores
    worse, so the looks stay pinned; where other draws score it as well, they are not."""

    pins = {"post.speckle_looks": {"alone": True}}
    best = {"post.speckle_looks": 5.0}
    trials = [(0.6, best), (0.62, {"post.speckle_looks": 6.5}), (0.9, {"post.speckle_looks": 7.0}),
              (0.7, {"post.speckle_looks": 4.0}), (0.95, {"post.speckle_looks": 2.0})]
    sharp = _on_draws(lambda v: 1.0 + 10 * math.log(v["post.speckle_looks"] / 5) ** 2)
    judged = trade_offs(pins, trials, best, sharp, [2, 3])["post.speckle_looks"]
    assert judged["pinned"] is True and judged["beyond"]["above"]["value"] == 6.5
    assert judged["beyond"]["below"]["value"] == 4.0 and judged["fresh"] == [1.0, 1.0]
    flat = _on_draws(lambda v: 1.0 + 0.1 * math.log(v["post.speckle_looks"] / 5) ** 2)
    assert trade_offs(pins, trials, best, flat, [2, 3])["post.speckle_looks"]["pinned"] is False
    # 15 % worse on average, but by 5 % on one draw and 25 % on the other: the two draws cannot tell
    def uneven(settings, seed):
        return [1.0 + (0.15 + (0.1 if seed == 3 else -0.1)) * (v != best) for v in settings]

    unsure = trade_offs(pins, trials, best, uneven, [2, 3])["post.speckle_looks"]
    assert unsure["beyond"]["above"]["rise"] == pytest.approx(0.15)
    assert unsure["beyond"]["above"]["error"] == pytest.approx(0.1) and unsure["pinned"] is None
    # 7 % worse on average, 1 % on one draw and 13 % on the other: not sure it scores as well either
    def wide(settings, seed):
        return [1.0 + (0.07 + (0.06 if seed == 3 else -0.06)) * (v != best) for v in settings]

    open_question = trade_offs(pins, trials, best, wide, [2, 3])["post.speckle_looks"]
    assert open_question["beyond"]["above"]["rise"] == pytest.approx(0.07) and open_question["pinned"] is None
    narrow = _on_draws(lambda v: 1.0 + 0.05 * (v != best))  # 5 % worse on both draws: surely under 10 %
    assert trade_offs(pins, trials, best, narrow, [2, 3])["post.speckle_looks"]["pinned"] is False
    even = _on_draws(lambda v: 1.0 + 0.15 * (v != best))
    assert trade_offs(pins, trials, best, even, [2, 3])["post.speckle_looks"]["pinned"] is True
    # at its range's end, a side with nothing beyond counts as held
    low = knob("post.speckle_looks").low
    edge = trade_offs(pins, [(0.6, {"post.speckle_looks": low}), (0.7, {"post.speckle_looks": 2 * low})],
                      {"post.speckle_looks": low},
                      _on_draws(lambda v: 1.0 + 10 * math.log(v["post.speckle_looks"] / low) ** 2), [2])
    edge = edge["post.speckle_looks"]
    assert edge["beyond"]["below"] == "range" and edge["pinned"] is True


def _gain_albedo(steep: float):
    """Only gain x albedo is seen (steeply, `steep`), and the looks alone."""
    def objective(v):
        seen = v["post.gain"] * v["seafloor.albedo"]
        return 1.0 + steep * math.log(seen / 0.1) ** 2 + 10 * math.log(v["post.speckle_looks"] / 5) ** 2
    return objective


BEST = {"post.gain": 0.25, "seafloor.albedo": 0.4, "post.speckle_looks": 5.0}


def test_the_ridge_is_the_line_the_best_trials_lie_along():
    rng = np.random.default_rng(1)
    gains = np.exp(rng.uniform(math.log(0.22), math.log(0.28), 40))
    looks = 5.0 * np.exp(rng.normal(0, 0.01, len(gains)))
    trials = [(1.0, {"post.gain": g, "seafloor.albedo": 0.1 / g, "post.speckle_looks": k})
              for g, k in zip(gains, looks)]
    trials += [(9.0, {"post.gain": g, "seafloor.albedo": 0.4, "post.speckle_looks": 5.0}) for g in (0.1, 0.5)]
    slopes = ridge("post.gain", BEST, trials)
    # albedo's log range is 2.94, gain's 4.2: albedo falls 4.2 / 2.94 of its range per unit of gain's
    assert slopes["post.gain"] == pytest.approx(1.0)
    assert slopes["seafloor.albedo"] == pytest.approx(-math.log(2.0 / 0.03) / math.log(0.95 / 0.05), rel=1e-6)
    assert abs(slopes["post.speckle_looks"]) < 0.1
    # the worst trials (off the ridge) are left out: with them in, the line would bend
    assert ridge("post.gain", BEST, trials[:2])["seafloor.albedo"] == 0.0  # too few trials to draw a line


def test_a_knob_moves_with_those_its_best_trials_rise_or_fall_with_and_no_others():
    """The best trials lie along gain x albedo = 0.1, with altitude rising with the near range (the grazing angle
    seen); the looks wander on their own; worse trials off both lines are not among the best tenth."""
    rng = np.random.default_rng(2)
    names = ["post.gain", "seafloor.albedo", "sonar.altitude", "sonar.near_range", "post.speckle_looks"]
    trials = []
    for g, a in zip(np.exp(rng.uniform(math.log(0.2), math.log(0.3), 60)), rng.uniform(5.0, 8.0, 60)):
        knobs = {"post.gain": g, "seafloor.albedo": 0.1 / g * math.exp(rng.normal(0, 0.02)), "sonar.altitude": a,
                 "sonar.near_range": 5 * a * math.exp(rng.normal(0, 0.02)),
                 "post.speckle_looks": 5.0 * math.exp(rng.normal(0, 0.2))}
        trials.append((1.0 + rng.uniform(0, 0.01), knobs))
    trials += [(5.0, {**trials[0][1], "seafloor.albedo": 0.4 * albedo}) for albedo in rng.uniform(0.5, 2.0, 300)]
    partners = moves_with(names, trials)
    assert [m for m, _ in partners["post.gain"]] == ["seafloor.albedo"] and partners["post.gain"][0][1] < -0.95
    assert [m for m, _ in partners["sonar.near_range"]] == ["sonar.altitude"]
    assert partners["sonar.near_range"][0][1] > 0.95 and partners["post.speckle_looks"] == []
    # a knob the best trials hold fixed moves with nothing, and nothing with it
    still = moves_with(names, [(v, {**knobs, "post.gain": 0.25}) for v, knobs in trials])
    assert still["post.gain"] == [] and all(m != "post.gain" for p in still.values() for m, _ in p)
    assert moves_with(names, trials[:2]) == {n: [] for n in names}  # too few trials to tell


def test_a_ridge_the_search_did_not_follow_is_profiled_and_the_knobs_on_it_are_not_called_pinned():
    """The search tried gain 30 % away only with albedo where it was (scoring worse), and its best trials lie along
    gain x albedo = 0.1 within 10 %: its trials alone call gain pinned; holding gain 15 % away and following the
    line (then CMA-ES) finds an albedo scoring as well. The looks, seen alone, stay pinned either way."""
    objective = _gain_albedo(20.0)
    rng = np.random.default_rng(0)
    gains = np.exp(rng.uniform(math.log(0.23), math.log(0.27), 40))
    trials = [(objective(v), v) for v in ({**BEST, "post.gain": g, "seafloor.albedo": 0.1 / g} for g in gains)]
    trials += [(objective(v), v) for v in ({**BEST, "post.gain": g} for g in (0.17, 0.33))]
    trials += [(objective(v), v) for v in ({**BEST, "post.speckle_looks": k} for k in (3.0, 8.0))]
    pins = sensitivity(BEST, _on_draws(objective))
    assert all(p["alone"] for p in pins.values())
    seen = trade_offs(pins, trials, BEST, _on_draws(objective, lambda s: 0.2 * s), [1, 2, 3])
    assert seen["post.gain"]["pinned"] is True  # what the search's trials alone claim
    profiled = trade_offs(pins, trials, BEST, _on_draws(objective, lambda s: 0.2 * s), [1, 2, 3], 9, seed=0)
    gain = profiled["post.gain"]
    assert gain["pinned"] is False and profiled["seafloor.albedo"]["pinned"] is False
    for side, factor in (("below", 0.85), ("above", 1.15)):
        assert gain["beyond"][side]["profiled"] and gain["beyond"][side]["value"] == pytest.approx(0.25 * factor)
        assert gain["beyond"][side]["rise"] < 0.01  # on the line: as good as the calibrated preset
    assert profiled["post.speckle_looks"]["pinned"] is True
    # held 15 % away, nearer than the trials at 3 and 8: the looks' rivals are the profile's, and still worse
    looks = profiled["post.speckle_looks"]["beyond"]
    assert [looks[s]["value"] for s in ("below", "above")] == [pytest.approx(4.25), pytest.approx(5.75)]
    # what made up for the held gain: albedo, on the line gain x albedo = 0.1 (0.4 / 0.85)
    lines = "\n".join(sensitivity_lines(profiled, BEST, 9))
    assert "0.212 (profile): +0% ± 0% (with seafloor.albedo 0.471) |" in lines


def test_the_profile_searches_the_other_knobs_where_the_trials_show_no_ridge():
    """Every trial held albedo where it was: the line through them is flat, so its point 15 % along gain scores
    worse; the CMA-ES generations from there find the albedo that makes up for it."""
    objective = _gain_albedo(20.0)
    trials = [(objective(v), v) for v in ({**BEST, "post.gain": g} for g in np.linspace(0.2, 0.3, 30))]
    found = profile([("post.gain", "above")], BEST, trials, _on_draws(objective), 17, seed=0)
    best = found["post.gain", "above"]
    assert best["post.gain"] == pytest.approx(0.25 * 1.15)
    on_line = objective({**BEST, "post.gain": 0.25 * 1.15}) - 1.0  # the line's point: 20 x log(1.15)² = 0.39
    assert on_line > 0.3 and objective(best) - 1.0 < RISE  # a rise too small to pin gain
    assert best["seafloor.albedo"] == pytest.approx(0.4 / 1.15, rel=0.1)
    once = profile([("post.gain", "above")], BEST, trials, _on_draws(objective), 1, seed=0)  # the line's point alone
    assert objective(once["post.gain", "above"]) - 1.0 == pytest.approx(on_line)
    # with albedo left out of the search, nothing makes up for the held gain
    alone = profile([("post.gain", "above")], BEST, trials, _on_draws(objective), 17, seed=0,
                    searched=["post.speckle_looks"])
    assert alone["post.gain", "above"]["seafloor.albedo"] == pytest.approx(BEST["seafloor.albedo"])
    assert objective(alone["post.gain", "above"]) - 1.0 == pytest.approx(on_line)


def test_each_pair_of_knobs_that_move_together_is_drawn_once(tmp_path):
    pins = {"post.gain": {"moves_with": [("seafloor.albedo", -0.97), ("post.speckle_looks", 0.6)]},
            "seafloor.albedo": {"moves_with": [("post.gain", -0.97)]},
            "post.speckle_looks": {"moves_with": [("post.gain", 0.6)]}}
    assert pairs(pins) == [("post.gain", "seafloor.albedo", -0.97), ("post.gain", "post.speckle_looks", 0.6)]
    rng = np.random.default_rng(3)
    trials = [(1.0 + rng.uniform(0, 0.1), {**BEST, "post.gain": g, "seafloor.albedo": 0.1 / g})
              for g in rng.uniform(0.2, 0.3, 50)]
    judged = {"post.gain × seafloor.albedo": {"knobs": ["post.gain", "seafloor.albedo"], "power": 1,
                                              "calibrated": 0.1, "pinned": True}}
    assert ridges_figure(pins, trials, BEST, tmp_path / "ridges.png", judged)
    assert (tmp_path / "ridges.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    alone = {name: {"moves_with": []} for name in BEST}
    assert pairs(alone) == [] and not ridges_figure(alone, trials, BEST, tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()


def _two_ridges(steep: float):
    """gain x albedo seen (steeply, `steep`), altitude : near range seen as steeply, and the looks alone."""
    def objective(v):
        return (1.0 + steep * math.log(v["post.gain"] * v["seafloor.albedo"] / 0.1) ** 2
                + 20 * math.log(v["sonar.altitude"] / v["sonar.near_range"] / 0.2) ** 2
                + 10 * math.log(v["post.speckle_looks"] / 5) ** 2)
    return objective


TWO = {"post.gain": 0.25, "seafloor.albedo": 0.4, "sonar.altitude": 10.0, "sonar.near_range": 50.0,
       "post.speckle_looks": 5.0}


def _along_two_ridges(objective, seed: int = 4):
    """The search's best trials: along both ridges within 2 %, never 15 % off either line."""
    rng = np.random.default_rng(seed)
    trials = []
    for g, a in zip(np.exp(rng.uniform(math.log(0.2), math.log(0.3), 80)), rng.uniform(8.0, 12.0, 80)):
        v = {"post.gain": g, "seafloor.albedo": 0.1 / g * math.exp(rng.normal(0, 0.02)), "sonar.altitude": a,
             "sonar.near_range": a / 0.2 * math.exp(rng.normal(0, 0.02)),
             "post.speckle_looks": 5.0 * math.exp(rng.normal(0, 0.2))}
        trials.append((objective(v), v))
    return trials


def test_a_pair_that_trades_is_judged_together_the_ratio_or_product_the_chips_see():
    """Neither gain nor albedo, altitude nor near range is pinned alone: each trades along its line. What the
    chips see of each pair, the product gain x albedo and the ratio altitude : near range, held 15 % away by the
    profile scores worse on other draws: pinned together. The search's trials never went that far off the lines,
    so without a profile the report cannot tell; where the product is seen only faintly, it is not pinned."""
    objective = _two_ridges(20.0)
    trials = _along_two_ridges(objective)
    draws = _on_draws(objective, lambda s: 0.2 * s)
    pins = trade_offs(sensitivity(TWO, draws), trials, TWO, draws, [1, 2, 3], 9, seed=0)
    assert [pins[n]["pinned"] for n in TWO] == [False, False, False, False, True]
    judged = together(pins, trials, TWO, draws, [1, 2, 3], 9, seed=0)
    assert set(judged) == {"post.gain × seafloor.albedo", "sonar.altitude : sonar.near_range"}
    product, ratio = judged["post.gain × seafloor.albedo"], judged["sonar.altitude : sonar.near_range"]
    assert product["power"] == 1 and product["correlation"] < -0.9 and ratio["power"] == -1
    assert product["calibrated"] == pytest.approx(0.1) and ratio["calibrated"] == pytest.approx(0.2)
    for pair, centre in ((product, 0.1), (ratio, 0.2)):
        assert pair["pinned"] is True
        for side, factor in (("below", 0.85), ("above", 1.15)):
            found = pair["beyond"][side]
            assert found["profiled"] and found["value"] == pytest.approx(centre * factor)
            # 20 x log(1.15)² = 0.39 over the draws' mean of 1.4, the other knobs making up nothing more
            assert found["rise"] == pytest.approx(20 * math.log(factor) ** 2 / 1.4, abs=0.03)
    lines = "\n".join(together_lines(judged, 9))
    assert "| post.gain × seafloor.albedo | 0.1 | 0.085 (profile): +38% ± 0% | 0.115 (profile): +28% ± 0% | yes |" \
        in lines
    unprofiled = together(pins, trials, TWO, draws, [1, 2, 3])
    assert {pair["pinned"] for pair in unprofiled.values()} == {None}
    assert unprofiled["post.gain × seafloor.albedo"]["beyond"] == {"below": None, "above": None}
    faint = _two_ridges(0.5)  # 0.5 x log(1.15)² = 1 %: too little to pin the product
    faint_draws = _on_draws(faint)
    faint_pins = trade_offs(sensitivity(TWO, faint_draws), _along_two_ridges(faint), TWO, faint_draws, [1, 2], 9)
    faint_pairs = together(faint_pins, _along_two_ridges(faint), TWO, faint_draws, [1, 2], 9)
    assert faint_pairs["post.gain × seafloor.albedo"]["pinned"] is False
    assert faint_pairs["sonar.altitude : sonar.near_range"]["pinned"] is True
    assert together({n: {"alone": True, "moves_with": []} for n in TWO}, trials, TWO, draws, [1]) == {}


def test_the_pair_profile_holds_the_combination_and_every_knob_in_its_range():
    """Gain at the top of its range: held 15 % above, the product is reached only by albedo; no setting the
    profile scores puts gain beyond its range, and each holds the product where it should."""
    best = {"post.gain": 2.0, "seafloor.albedo": 0.05, "post.speckle_looks": 5.0}  # albedo at its range's foot
    objective = _gain_albedo(20.0)
    rng = np.random.default_rng(5)
    trials = [(objective(v), v) for v in ({**best, "post.gain": g, "seafloor.albedo": 0.1 / g * math.exp(
        rng.normal(0, 0.02))} for g in np.exp(rng.uniform(math.log(1.6), math.log(2.0), 60)))]
    pins = {"post.gain": {"alone": True, "moves_with": [("seafloor.albedo", -0.99)]},
            "seafloor.albedo": {"alone": True, "moves_with": [("post.gain", -0.99)]},
            "post.speckle_looks": {"alone": True, "moves_with": []}}
    scored = []

    def objectives(settings, seed=0):
        scored.extend(settings)
        return [objective(v) for v in settings]

    judged = together(pins, trials, best, objectives, [1, 2], 17)["post.gain × seafloor.albedo"]
    assert sum(v == best for v in scored) == 2  # the calibrated preset once a draw: the profile's rivals beside it
    assert max(v["post.gain"] for v in scored) <= knob("post.gain").high
    assert min(v["seafloor.albedo"] for v in scored) >= knob("seafloor.albedo").low
    for side, held in (("below", 0.085), ("above", 0.115)):
        near = [v for v in scored if abs(v["post.gain"] * v["seafloor.albedo"] / held - 1) < 0.05]
        assert len(near) > 8 and all(v["post.gain"] * v["seafloor.albedo"] == pytest.approx(held) for v in near)
        assert judged["beyond"][side]["value"] == pytest.approx(held)
    assert judged["pinned"] is True
