"""`sasmi calibrate`'s search: its Optuna studies in RUN/study.db, asked and told in batches, resumed exactly.

With --searches N, N searches share the search time, each its own sampler path over its own draw of the scenes:
single searches of one command can end where a classifier tells their chips from real ones very differently, and the
two-sample test on the chips calibrated to ranks them mostly as held-out chips do (calibrate.py keeps the one it tells
least; docs/calibrate.md). A rerun asks what an unbroken run asks: each trial's sampler is seeded by the seed, the
search and the trial's number (CMA-ES keeps its state in the study, not in the sampler), a search's trials depend on
no other search, and the trials a killed run had asked are scored as they were asked.
"""
from __future__ import annotations

import contextlib
import math
import time
import warnings
from pathlib import Path
from typing import Iterator

import numpy as np

from sasmi.errors import SasmiError
from sasmi.realism.preset_space import apply, knob
from sasmi.scene.preset import Preset

SEARCH_SEEDS = 1000  # scene seeds apart from one search to the next


def study_name(search: int) -> str:
    return "calibrate" if search == 0 else f"calibrate-{search}"


def sampler_for(cfg, x0: dict[str, float], number: int, search: int = 0):
    """The sampler that asks trial `number` of `search`, seeded by the seed, the search and that number alone: a rerun
    asks exactly what an unbroken run asks (CMA-ES keeps its state in the study, not in the sampler)."""
    import optuna

    entropy = [cfg.seed, number] if search == 0 else [cfg.seed, number, search]  # search 0: as with one search
    seed = int(np.random.SeedSequence(entropy).generate_state(1)[0])
    if cfg.sampler == "cmaes":
        with warnings.catch_warnings():  # x0 and sigma0 (the start preset, the first step) are deprecated from 4.9 on,
            warnings.simplefilter("ignore", FutureWarning)  # to go in 6.0 (pyproject pins optuna < 6)
            return optuna.samplers.CmaEsSampler(x0=x0, sigma0=cfg.step, seed=seed, warn_independent_sampling=False)
    return optuna.samplers.TPESampler(seed=seed, multivariate=True)


def open_studies(out: Path, cfg, x0: dict[str, float]) -> list:
    """The `cfg.searches` studies, made or continued; each one's trial 0 is the start preset."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = optuna.storages.RDBStorage(f"sqlite:///{(out / 'study.db').resolve()}")
    studies = []
    for search in range(cfg.searches):
        study = optuna.create_study(study_name=study_name(search), storage=storage,
                                    sampler=sampler_for(cfg, x0, 0, search), direction="minimize", load_if_exists=True)
        if not study.trials:
            study.enqueue_trial(x0)  # trial 0 is the start preset: the report's "before"
        studies.append(study)
    return studies


def searched_seconds(studies: list) -> float:
    """Wall time of the search, all searches and runs together: what --minutes counts."""
    return sum(float(s.user_attrs.get("seconds", 0.0)) for s in studies)


def lowest(study) -> float:
    """The study's best objective so far (infinite before its first trial is told)."""
    with contextlib.suppress(ValueError):
        return study.best_value
    return math.inf


def scene_seed(cfg, search: int) -> int:
    """The seed of the scenes a search's trials render: the seed for search 0 (as with one search), and draws no
    other search, the report nor the contenders' other draws (seed + 1 ... + 9) render for the others."""
    return cfg.seed + SEARCH_SEEDS * search


def next_search(studies: list, cfg) -> int | None:
    """The search that asks the next batch, or None once the budget (--minutes, --trials) is spent: each of the N
    searches runs for 1/N of it, the one furthest behind first."""
    seconds = [searched_seconds([s]) for s in studies]
    counts = [asked(s) for s in studies]
    if cfg.trials is not None and sum(counts) >= cfg.trials:  # shares rounded up: the last may get one fewer
        return None
    share = len(studies)
    running = [i for i in range(share) if seconds[i] < cfg.minutes * 60 / share
               and (cfg.trials is None or counts[i] < math.ceil(cfg.trials / share))]
    behind = (lambda i: (seconds[i], i)) if cfg.trials is None else (lambda i: (counts[i], i))
    return min(running, key=behind) if running else None


def asked(study) -> int:
    """Trials asked so far: the start preset waits in the queue until the first is asked."""
    import optuna

    return sum(t.state != optuna.trial.TrialState.WAITING for t in study.get_trials(deepcopy=False))


def interrupted_trials(study, cfg) -> list:
    """The trials a killed run asked and never told: those whose knobs were all drawn, to be scored as asked;
    the others failed."""
    import optuna

    asked = []
    for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        if set(t.params) == set(cfg.params):
            asked.append(optuna.trial.Trial(study, t._trial_id))
        else:
            study._storage.set_trial_state_values(t._trial_id, optuna.trial.TrialState.FAIL)
    return asked


def first_scene(study, trial, cfg) -> int:
    """The first of the scenes the trial renders: 0, or with --redraw-scenes, the first of its CMA-ES generation's own
    draw (the start preset, asked before the first generation, renders the first draw)."""
    generation = study._storage.get_trial_system_attrs(trial._trial_id).get("cma:generation")
    return 0 if not cfg.redraw_scenes or generation is None else cfg.chips * (generation + 1)


def suggest(trial, names: tuple[str, ...]) -> dict[str, float]:
    values = {}
    for name in names:
        k = knob(name)
        low = max(k.low, 1e-6) if k.log else k.low
        values[name] = trial.suggest_float(name, low, k.high, log=k.log)
    return values


def run_batch(study, search: int, preset: Preset, cfg, x0: dict[str, float], run, width: int) -> None:
    """`width` trials of `search` asked (or those a killed run asked), scored together and told; their wall time is
    added to the search's time."""
    start = time.perf_counter()
    trials = interrupted_trials(study, cfg)
    for _ in range(width - len(trials)):
        study.sampler = sampler_for(cfg, x0, len(study.get_trials(deepcopy=False)), search)
        trials.append(study.ask())
    raws = [apply(preset.raw, suggest(t, cfg.params)) for t in trials]
    scores = run(raws, scene_seed(cfg, search), [first_scene(study, t, cfg) for t in trials])
    for trial, s in zip(trials, scores):
        for key, value in s.items():
            if key != "objective":
                trial.set_user_attr(key, value)
        study.tell(trial, s["objective"])
    study.set_user_attr("seconds", searched_seconds([study]) + time.perf_counter() - start)


def calibrated_trial(study, preset: Preset, cfg, final, objectives_of, draws: list[int]) -> tuple[dict, object]:
    """(preset, trial): of the `cfg.contenders` best trials on the search's scenes whose presets draw every scene of the
    report (and of `cfg.final_chips` more, seed `final.seed`) within the preset's rules, the one scoring lowest on
    average over other `draws` of those scenes (`objectives_of(settings, seed)`). A search's best owes part of its
    lead to the draws it was fitted to; a trial saw only its own scenes, and a preset must hold for every draw."""
    import optuna

    done = sorted((t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE), key=lambda t: t.value)
    valid = []
    for trial in done:
        raw = apply(preset.raw, {n: trial.params[n] for n in cfg.params})
        try:
            candidate = Preset.from_dict(raw, path=preset.path)
            for seed in (final.seed, final.seed + 1):
                for i in range(cfg.final_chips):
                    candidate.sample(seed, i)
        except SasmiError:
            continue
        valid.append((raw, trial))
        if len(valid) == cfg.contenders:
            break
    if not valid:
        raise SasmiError(f"no trial's preset draws {cfg.final_chips} valid scenes; rerun with a larger --minutes")
    scores = np.mean([objectives_of([t.params for _, t in valid], seed) for seed in draws], axis=0)
    chosen = int(np.argmin(scores))
    study.set_user_attr("calibrated_trial", valid[chosen][1].number)
    study.set_user_attr("contenders", {"draws": len(draws),
                                       "scores": [[t.number, t.value, float(v)] for (_, t), v in zip(valid, scores)]})
    return valid[chosen]


@contextlib.contextmanager
def full_disk_named(out: Path) -> Iterator[None]:
    """SQLite's own words for a full disk, through SQLAlchemy, as one line naming the study."""
    try:
        yield
    except Exception as e:
        if "disk is full" in str(e) or "disk I/O error" in str(e):
            raise SasmiError(f"{out}/study.db: cannot write (the disk is full); free some space and rerun the "
                             "same command to continue") from None
        raise
