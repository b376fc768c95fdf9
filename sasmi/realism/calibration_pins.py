"""Which knobs the chips pin: what `sasmi calibrate`'s report says of each calibrated value.

A knob is pinned when moving it alone raises the objective (`sensitivity`) and no setting holding it more
than SPAN away scores as well on other draws of the search's scenes (`trade_offs`). The rivals are the
search's own best trials beyond SPAN and, where those leave a knob pinned or undecided, a profile: the knob
held SPAN away and every other knob searched again from the ridge the best trials lie along. What a knob that
trades trades with shows in the best trials, spread along the ridge (`moves_with`), and what the chips pin of
such a pair, its ratio or its product, is judged as a knob is (`together`).
"""
from __future__ import annotations

import math

import numpy as np

from sasmi.realism.preset_space import knob

STEP = 0.2  # each knob is moved alone by this share of its search range (on its search scale), down and up ...
RISE = 0.1  # ... and the chips pin it when the calibrated objective rises by at least this share, on average,
SPAN = 0.15  # ... and the best settings holding it further than this share away score RISE worse on other draws
SIGMA = 0.05  # the profile's CMA-ES step, as a share of each knob's search range: a local search from the ridge
POPULATION = 8  # the profile's settings a generation
PARTNER = 0.5  # a knob moves with another where they correlate at least this much among the best trials ...
SURE = 3.5  # ... and the correlation's Fisher z is this many standard errors from 0: chance, over 14 knobs' 91
# pairs, names one pair in 20 runs
PAIRS = 6  # pairs of knobs that move together judged (and drawn), the most correlated first
MOVED_TOO = 3  # knobs a rival moved furthest, named beside it: where to look for what made up for the held one


def _unit(name: str):
    """(to, back): a knob's value to its place in its search range (0 to 1, log where searched so) and back."""
    k = knob(name)
    to, back = (math.log, math.exp) if k.log else (float, float)
    low, high = to(k.low), to(k.high)
    return (lambda x: (to(min(max(x, k.low), k.high)) - low) / (high - low),
            lambda u: min(max(back(low + min(max(u, 0.0), 1.0) * (high - low)), k.low), k.high))


def sensitivity(best: dict[str, float], objectives_of) -> dict[str, dict]:
    """Per knob, the calibrated objective's mean rise with that knob alone moved STEP of its range down and up
    (clipped to the range); objectives_of(settings) scores a list of settings of every knob at once (on the
    trials' workers). A knob whose moves leave the objective where it was is one the chips cannot pin."""
    moves = {}
    for name, value in best.items():
        to, back = _unit(name)
        moves[name] = [back(to(value) + sign * STEP) for sign in (-1, 1)]
    base, *moved = objectives_of([best, *({**best, name: m} for name in moves for m in moves[name])])
    result = {}
    for i, name in enumerate(moves):
        rise = float(np.mean(moved[2 * i:2 * i + 2]) - base)
        result[name] = {"moved": moves[name], "rise": rise, "share": rise / max(base, 1e-12),
                        "alone": rise >= RISE * base}
    return result


def _beyond(value_of, centre: float, low: float, high: float,
            trials: list[tuple[float, dict]]) -> dict[str, dict | str | None]:
    """Below and above: the knobs of the trial scoring best on the search's scenes among those whose value_of(knobs)
    (None where a trial lacks it) lies more than SPAN of `centre` away on that side; "range" where the values
    reachable (`low` to `high`) end within SPAN, None where the search tried nothing there."""
    band = SPAN * abs(centre)
    found = {}
    for side, beyond, ends in (("below", lambda x: x < centre - band, centre - band <= low),
                               ("above", lambda x: x > centre + band, centre + band >= high)):
        there = [(value, knobs) for value, knobs in trials if (x := value_of(knobs)) is not None and beyond(x)]
        found[side] = min(there, key=lambda t: t[0])[1] if there else ("range" if ends else None)
    return found


def best_tenth(names: list[str], trials: list[tuple[float, dict]]) -> list[tuple[float, dict]]:
    """The best tenth of the trials (objective, knobs) that set every knob of `names`, at least twice as many as
    knobs: the trials that spread along the objective's ridges."""
    done = sorted((t for t in trials if all(n in t[1] for n in names)), key=lambda t: t[0])
    return done[:max(2 * len(names) + 1, len(done) // 10)]


def _best_units(names: list[str], trials: list[tuple[float, dict]]) -> np.ndarray | None:
    """(trials, knobs) `best_tenth` in search-range units, `names` in order; None with fewer than 3."""
    top = best_tenth(names, trials)
    return np.array([[_unit(n)[0](knobs[n]) for n in names] for _, knobs in top]) if len(top) >= 3 else None


def ridge(name: str, best: dict[str, float], trials: list[tuple[float, dict]]) -> dict[str, float]:
    """Per knob, how far it moves along its search range per unit of `name`'s among the best tenth of the trials:
    the line along which knobs trade, which CMA-ES's last generations follow. 0 where those trials hold `name`
    fixed."""
    names = list(best)
    u = _best_units(names, trials)
    held = None if u is None else u[:, names.index(name)]
    if held is None or held.var() < 1e-12:
        return {n: 0.0 for n in names}
    return {n: float(np.cov(held, u[:, j])[0, 1] / held.var(ddof=1)) for j, n in enumerate(names)}


def moves_with(moving: list[str], trials: list[tuple[float, dict]]) -> dict[str, list[tuple[str, float]]]:
    """Per knob of `moving`, the others of `moving` it rises or falls with among the best tenth of the trials
    (correlation at least PARTNER either way, on their search scales, and SURE standard errors from none), the
    strongest first: where the objective is flat along a line, CMA-ES's best trials spread along it, so a knob
    that trades shows what it trades with (gain falling as albedo rises, altitude rising with range)."""
    u = _best_units(moving, trials)
    if u is None:
        return {n: [] for n in moving}
    spread = u.std(axis=0)
    kept = spread > 1e-9
    r = np.zeros((len(moving), len(moving)))
    r[np.ix_(kept, kept)] = np.corrcoef(u[:, kept], rowvar=False)
    least = max(PARTNER, math.tanh(SURE / math.sqrt(max(len(u) - 3, 1))))
    return {n: sorted(((m, float(r[i, j])) for j, m in enumerate(moving) if j != i and abs(r[i, j]) >= least),
                      key=lambda pair: -abs(pair[1]))
            for i, n in enumerate(moving)}


def _local_search(starts: dict, free: dict, settle, objectives_of, budget: int, seed: int) -> dict:
    """Per key, the setting scoring best on the search's scenes: its start, then CMA-ES generations over its `free`
    knobs (search-range units, from the start), settle(key, setting) restoring what the key holds (None where it
    cannot: not scored), `budget` settings a key in all, all keys scored together."""
    import cmaes

    found = dict(starts)
    scores = dict(zip(found, objectives_of(list(found.values())))) if found else {}
    searches = {}
    for i, key in enumerate(found):
        if free[key] and budget > 1:
            state = int(np.random.SeedSequence([seed, i]).generate_state(1)[0])
            mean = np.array([_unit(n)[0](found[key][n]) for n in free[key]])
            searches[key] = cmaes.CMA(mean=mean, sigma=SIGMA, bounds=np.array([[0.0, 1.0]] * len(free[key])),
                                      seed=state, population_size=POPULATION)
    for _ in range((budget - 1) // POPULATION if searches else 0):
        asked = [(key, u, settle(key, {**found[key], **{n: _unit(n)[1](x) for n, x in zip(free[key], u)}}))
                 for key, cma in searches.items() for u in (cma.ask() for _ in range(POPULATION))]
        scored = [setting for _, _, setting in asked if setting is not None]
        got = iter(objectives_of(scored) if scored else [])
        values = [math.inf if setting is None else next(got) for _, _, setting in asked]
        worst = max((v for v in values if math.isfinite(v)), default=1.0)
        for key, cma in searches.items():  # ranks are what CMA-ES uses: one it could not score ranks last
            cma.tell([(u, v if math.isfinite(v) else 10 * abs(worst) + 1)
                      for (k, u, _), v in zip(asked, values) if k == key])
        for (key, _, setting), value in zip(asked, values):
            if value < scores[key]:
                scores[key], found[key] = value, setting
    return found


def pairs(pins: dict[str, dict]) -> list[tuple[str, str, float]]:
    """(knob, knob, correlation) of each pair one of them *moves with*, the strongest first, at most PAIRS."""
    found = {tuple(sorted((name, other))): r for name, p in pins.items() for other, r in p.get("moves_with", [])}
    return sorted(((a, b, r) for (a, b), r in found.items()), key=lambda pair: -abs(pair[2]))[:PAIRS]


def profile(wanted: list[tuple[str, str]], best: dict[str, float], trials: list[tuple[float, dict]],
            objectives_of, budget: int, seed: int, searched: list[str] | None = None) -> dict[tuple[str, str], dict]:
    """Per (knob, side) in `wanted`, the setting scoring best on the search's scenes with the knob held SPAN below
    or above its calibrated value: the first on the ridge (`ridge`) through the calibrated preset, then CMA-ES
    generations from there over the other knobs (those `searched`, default all: the ones that move the objective
    are what can make up for the held one), `budget` settings a side in all, all sides scored together."""
    names = list(best)
    slopes = {name: ridge(name, best, trials) for name in dict.fromkeys(n for n, _ in wanted)}  # one line, both sides
    starts = {}
    for name, side in wanted:
        to = _unit(name)[0]
        held = best[name] * (1 - SPAN if side == "below" else 1 + SPAN)
        moved = to(held) - to(best[name])
        starts[name, side] = {n: held if n == name else _unit(n)[1](_unit(n)[0](best[n]) + slopes[name][n] * moved)
                              for n in names}
    free = {(name, side): [n for n in (names if searched is None else searched) if n != name] for name, side in wanted}
    return _local_search(starts, free, lambda key, setting: setting, objectives_of, budget, seed)


def _rises(settings: list[dict], objectives_of, draws: list[int],
           fresh: np.ndarray | None = None) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """`fresh`, the calibrated preset's objective on each of `draws` (None: the first setting's, scored here), and
    each setting's mean rise over it (as a share of its mean) with the standard error over the draws: the same
    scenes for all, so the comparison is paired."""
    scores = np.array([objectives_of(settings, seed) if settings else [] for seed in draws],
                      dtype=float).reshape(len(draws), len(settings))  # (draws, settings)
    fresh = scores[:, 0] if fresh is None else np.asarray(fresh, dtype=float)
    rises = []
    for j in range(len(settings)):
        d = (scores[:, j] - fresh) / float(np.mean(fresh))
        rises.append((float(np.mean(d)), float(np.std(d, ddof=1) / math.sqrt(len(d))) if len(d) > 1 else 0.0))
    return fresh, rises


def _pinned(alone: bool, sides: dict) -> bool | None:
    """False where a side scores less than RISE worse by more than twice its rise's standard error over the draws;
    True where both score RISE or more worse on average, and worse by more than twice that error; None where the
    draws cannot tell either or a side had no rival."""
    found = [v for v in sides.values() if isinstance(v, dict)]
    if not alone or any(v["rise"] + 2 * v["error"] < RISE for v in found):
        return False
    if None in sides.values() or any(v["rise"] < RISE or v["rise"] < 2 * v["error"] for v in found):
        return None
    return True


def trade_offs(pins: dict[str, dict], trials: list[tuple[float, dict]], best: dict[str, float], objectives_of,
               draws: list[int], profile_budget: int = 0, seed: int = 0) -> dict[str, dict]:
    """`sensitivity`'s pins with what a search can see. A search fits its own scenes' draws, so its scores cannot
    tell two good settings apart: for each knob that moves the objective alone, the trials (objective, knobs)
    scoring best with it more than SPAN below and above its calibrated value are scored again, beside the
    calibrated preset, on other `draws` of the search's scenes (`objectives_of(settings, seed)`, as in
    `sensitivity`, on the scenes of that seed). Knobs that trade (gain against albedo, altitude against range)
    each move the objective alone, yet along their ridge a value further away scores as well. The search's
    trials may not reach along a ridge: with `profile_budget`, each side of a knob they leave pinned or
    undecided is profiled too (`profile`, that many settings a side) and the lower of the two rises counts.
    pinned: True where a knob moves the objective alone and both sides score at least RISE worse on average,
    by more than twice the rise's standard error over the draws (or the knob's range ends there); False where
    one scores less than RISE worse by as much; None where the draws cannot tell or nothing was scored that far on
    a side."""
    result = {name: {**p, "beyond": {}} for name, p in pins.items()}
    trialled = {}
    for name, p in pins.items():
        k = knob(name)
        sides = _beyond(lambda knobs: knobs.get(name), best[name], k.low, k.high, trials) if p["alone"] else {}
        for side, rival in sides.items():
            result[name]["beyond"][side] = None if isinstance(rival, dict) else rival  # None till scored
            if isinstance(rival, dict):
                trialled[name, side] = rival
    moving = [name for name, p in pins.items() if p["alone"]]

    def describe(name, setting):
        return {"value": float(setting[name]), "moved_too": _moved_too(setting, best, moving, {name})}

    fresh = _judge(result, trialled, best, objectives_of, draws, describe, profiled=False)
    wanted = [(name, side) for name, r in result.items() if r["alone"] and _pinned(True, r["beyond"]) is not False
              for side, rival in r["beyond"].items() if rival != "range" and best[name] != 0]
    if profile_budget and wanted:
        _judge(result, profile(wanted, best, trials, objectives_of, profile_budget, seed, moving), best,
               objectives_of, draws, describe, profiled=True, fresh=fresh)
    partners = moves_with([name for name, p in pins.items() if p["alone"]], trials)
    for name, r in result.items():
        r.update(fresh=[float(f) for f in fresh], pinned=_pinned(r["alone"], r["beyond"]),
                 moves_with=partners.get(name, []))
    return result


def _moved_too(setting: dict, best: dict[str, float], moving: list[str], held: set[str]) -> list[list]:
    """[knob, value] of the MOVED_TOO knobs of `moving` but `held` that `setting` moves furthest from `best` on their
    search scales: where to look for what let a rival hold a knob or pair away and score about as well (a knob the
    objective barely sees wanders far in any trial)."""
    far = sorted(((abs(_unit(n)[0](setting[n]) - _unit(n)[0](best[n])), n) for n in moving
                  if n not in held and n in setting), reverse=True)
    return [[n, float(setting[n])] for moved, n in far[:MOVED_TOO] if moved > 1e-6]


def _judge(result: dict, rivals: dict[tuple[str, str], dict], best: dict[str, float], objectives_of,
           draws: list[int], describe, profiled: bool, fresh: np.ndarray | None = None) -> np.ndarray:
    """Score `rivals` ((key, side) -> setting) beside `best` on `draws`; each becomes its side's rival in `result`
    (as describe(key, setting) tells it) where it rises less than the one there. The calibrated preset's scores on
    the draws: `fresh` where given (the renders are the same for the same draw, so they are not scored again)."""
    settings = [] if fresh is not None else [best]
    for rival in rivals.values():
        if rival not in settings:
            settings.append(rival)
    fresh, rises = _rises(settings, objectives_of, draws, fresh)
    for (key, side), rival in rivals.items():
        rise, error = rises[settings.index(rival)]
        old = result[key]["beyond"][side]
        if not isinstance(old, dict) or rise < old["rise"]:
            result[key]["beyond"][side] = {**describe(key, rival), "rise": rise, "error": error,
                                           "profiled": profiled}
    return fresh


def _combination(a: str, b: str, power: int):
    """knobs -> a x b^power, None where a trial lacks either or b is not positive."""
    return lambda knobs: knobs[a] * knobs[b] ** power if a in knobs and b in knobs and knobs[b] > 0 else None


def together(pins: dict[str, dict], trials: list[tuple[float, dict]], best: dict[str, float], objectives_of,
             draws: list[int], profile_budget: int = 0, seed: int = 0,
             fresh: list[float] | None = None) -> dict[str, dict]:
    """What the chips pin of each pair of knobs that move together (`pairs`): their ratio where they rise together
    (altitude : near range), their product where one falls as the other rises (gain × albedo), judged as
    `trade_offs` judges a knob: held SPAN below and above its calibrated value by the best trials there and, where
    those leave it pinned or undecided, a profile (the pair's first knob set to hold the combination, the second and
    every other moving knob searched again). `fresh`: the calibrated preset's objective on `draws`, where
    `trade_offs` scored it. Per pair, by its label: knobs, power (the second knob's), correlation, calibrated (the
    combination's value), beyond and pinned."""
    result, combos, trialled = {}, {}, {}
    for a, b, r in pairs(pins):
        if best[a] <= 0 or best[b] <= 0:
            continue  # no ratio or product of a knob at 0
        power = -1 if r > 0 else 1
        label = f"{a} {':' if power < 0 else '×'} {b}"
        value = combos[label] = _combination(a, b, power)
        ka, kb = knob(a), knob(b)
        ends = [x * y ** power for x in (ka.low, ka.high) for y in (kb.low, kb.high) if y > 0]
        ends += [math.inf if power < 0 else 0.0] if kb.low <= 0 else []
        result[label] = {"knobs": [a, b], "power": power, "correlation": r, "calibrated": value(best), "beyond": {}}
        for side, rival in _beyond(value, value(best), min(ends), max(ends), trials).items():
            result[label]["beyond"][side] = None if isinstance(rival, dict) else rival  # None till scored
            if isinstance(rival, dict):
                trialled[label, side] = rival
    if not result:
        return {}

    moving = [n for n, p in pins.items() if p["alone"]]

    def describe(label, setting):
        return {"value": float(combos[label](setting)),
                "moved_too": _moved_too(setting, best, moving, set(result[label]["knobs"]))}

    fresh = _judge(result, trialled, best, objectives_of, draws, describe, profiled=False, fresh=fresh)
    wanted = [(label, side) for label, r in result.items() if _pinned(True, r["beyond"]) is not False
              for side, rival in r["beyond"].items() if rival != "range"]
    if profile_budget and wanted:
        held = {(label, side): result[label]["calibrated"] * (1 - SPAN if side == "below" else 1 + SPAN)
                for label, side in wanted}

        def settle(key, setting):  # the first knob set so that the pair holds its combination, None out of range
            a, b = result[key[0]]["knobs"]
            need, k = held[key] / setting[b] ** result[key[0]]["power"], knob(a)
            inside = k.low * (1 - 1e-9) <= need <= k.high * (1 + 1e-9)  # a range's end reached by rounding
            return {**setting, a: min(max(need, k.low), k.high)} if inside else None

        starts, free = {}, {}
        for key in wanted:
            a, b = result[key[0]]["knobs"]
            f, power = held[key] / result[key[0]]["calibrated"], result[key[0]]["power"]
            # both knobs half the way, else the second alone, else the first alone
            for moved in (best[b] * f ** (0.5 / power), best[b] * f ** (1 / power), best[b]):
                start = settle(key, {**best, b: moved}) if knob(b).low <= moved <= knob(b).high else None
                if start is not None:
                    starts[key], free[key] = start, [n for n in moving if n != a]
                    break
        _judge(result, _local_search(starts, free, settle, objectives_of, profile_budget, seed), best,
               objectives_of, draws, describe, profiled=True, fresh=fresh)
    for r in result.values():
        r["pinned"] = _pinned(True, r["beyond"])
    return result


def what_the_chips_pin(best: dict[str, float], trials: list[tuple[float, dict]], objectives_of, draws: list[int],
                       profile_budget: int = 0, seed: int = 0) -> tuple[dict[str, dict], dict[str, dict]]:
    """Each knob's verdict (`sensitivity`, then `trade_offs`) and each moving pair's (`together`)."""
    pins = trade_offs(sensitivity(best, objectives_of), trials, best, objectives_of, draws, profile_budget, seed)
    fresh = next(iter(pins.values()))["fresh"] if pins else None
    return pins, together(pins, trials, best, objectives_of, draws, profile_budget, seed, fresh)
