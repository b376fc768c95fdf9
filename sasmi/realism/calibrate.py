"""`sasmi calibrate`: a preset fitted to a folder of unlabelled real chips, as a distribution.

Each trial sets the knobs (sasmi/realism/preset_space.py), renders the same `chips` scenes of the
candidate preset (the same random draws in every trial, so two trials differ by their knobs alone) and
scores them against the real chips:

    objective = mean over the checked statistics of min(d, 4)²  +  phi_weight x φ-FID ratio
                + distribution_weight x mean over the statistics of min(|AUC - 0.5| / tolerance, 4)²
                + variety_weight x max(0, 1 - recall / the real chips' own recall)

d is how many `sasmi stats --check` tolerances the renders' median lies from the real chips' (<= 1 passes), and the
gain's swing along track and the share of chips with a target found; the target sizes, the shadow level and the
target's offset from the centre row count only where most real chips show a target (sasmi.chips.compare); the φ-FID
ratio is the renders' FID to the real chips in φ over that of as many real chips to the rest (1: as close as real
chips are to each other), the renders' FID less the part of its small-sample bias that their own spread adds beyond
the real chips' (else renders too alike would score better than real chips); the objective and its parts:
sasmi/realism/calibration_objective.py. The first term pins what the statistics measure, the second the whole
distribution of looks; the third (off by default) each statistic's distribution, chip by chip, which a median within
tolerance leaves free and a classifier sees (the checked statistics and the nine of `sasmi evaluate`'s signature: each
one's ROC AUC, renders against real chips, over two standard errors of an AUC of one distribution); the fourth (off by
default) keeps them as varied as the real chips, which the φ-FID of a few renders does not (docs/calibrate.md says
what each did). Optuna's CMA-ES (or TPE) searches: --searches of them share the time, each over its own draw of the
scenes (sasmi/realism/calibration_study.py), and the one whose report renders `sasmi evaluate`'s two-sample test
tells least from the real chips is calibrated; the studies live in RUN/study.db, so a rerun continues them;
--minutes counts the search time of all searches and runs together.
"""
from __future__ import annotations

import contextlib
import functools
import json
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from sasmi.errors import SasmiError, Stopped
from sasmi.images import check_room, write_text
from sasmi.preprocess import check_size
from sasmi.realism.calibration_objective import RealChips, Weights, final_score, real_chips, score
from sasmi.realism.calibration_study import (asked, calibrated_trial, full_disk_named, lowest, next_search,
                                             open_studies, run_batch, scene_seed, searched_seconds)
from sasmi.realism.preset_space import DEFAULT_KNOBS, apply, check_knobs, start_values
from sasmi.scene.preset import Preset, load_preset

SAMPLERS = ("cmaes", "tpe")
FAILED = 1e3  # objective of a knob setting that makes no valid preset
# other draws of the trials' scenes the calibrated trial is chosen on (and as many more its knobs are judged on)
FRESH_DRAWS = 4
ROOM = 20_000_000  # bytes: a study of thousands of trials, the report's figures
# what the gradient refines: the differentiable render's parameters but the source level, which post.gain searches
REFINED = ("seafloor.roughness", "seafloor.albedo", "sonar.elevation")


@dataclass(frozen=True)
class CalibrateConfig:
    params: tuple[str, ...] = DEFAULT_KNOBS  # knobs searched; every other field keeps the start's value
    minutes: float = 30.0  # search time of all runs of the study together
    trials: int | None = None  # or stop after this many trials, whichever comes first
    chips: int = 32  # scenes rendered per trial; their medians and φ are scored
    size: int = 128  # render size and statistics size (the statistics' thresholds are stated at 128 px)
    spp: int = 4  # samples per pixel: the render time at 128 px hardly depends on it
    sampler: str = "cmaes"  # "cmaes": Optuna's CMA-ES started at the start preset; "tpe": Optuna's TPE
    # CMA-ES's first step, a fraction of each knob's range (None: Optuna's own, 1/6). Begun at 0.05, two searches
    # fell faster but fitted their own scenes more than other draws: no better on held-out chips (docs/calibrate.md)
    step: float | None = None
    # searches sharing the time, each its own sampler path over its own draw of the scenes; the one whose report
    # renders a classifier tells least from the real chips is calibrated, the others written beside it. 1: over two
    # seeds, two searches of one search's time each were no better on held-out chips (docs/calibrate.md)
    searches: int = 1
    # each CMA-ES generation renders its own draw of the scenes (all its trials the same one), so that no search fits
    # one draw. Off: two redrawn searches ended closer together on held-out chips, but no better (docs/calibrate.md)
    redraw_scenes: bool = False
    phi_weight: float = 1.0  # weight of the φ-FID ratio against the mean squared tolerance distance
    # weight of the statistics' AUCs, chip by chip: what keeps most renders from lying on one side of most real chips
    # (off by default: from muscle_paper it cost the φ-FID ratio, and a classifier told the renders as well)
    distribution_weight: float = 0.0
    variety_weight: float = 0.0  # weight of the recall shortfall: what keeps the renders as varied as the real chips
    # φ-FID less the small-sample bias the renders' own spread adds beyond the real chips' (False: the plain FID)
    spread_correction: bool = True
    final_chips: int = 200  # renders of the start and the calibrated preset in the report, other scenes
    seed: int = 0  # preset draws of the trials; the report's renders use seed + 1
    workers: int = 1  # local Dask processes scoring trials side by side (1: here, one after another)
    scheduler: str | None = None  # or an existing Dask cluster's address
    # best trials on the search's scenes scored again on other draws, the lowest calibrated (1: the search's best)
    contenders: int = 8
    # settings tried a side of each knob the trials leave pinned or undecided, the knob held 15 % away: its profile
    profile_trials: int = 9  # the line's point and one CMA-ES generation
    # then this many steps of `sasmi fit-scene` (gradients through Mitsuba) from the calibrated preset on REFINED,
    # kept only where they lower the objective on the report's renders (the gradient sees φ, not the statistics)
    refine_steps: int = 0

    def validate(self) -> "CalibrateConfig":
        check_knobs(self.params)
        check_size(self.size, "--size")
        if self.sampler not in SAMPLERS:
            raise SasmiError(f"--sampler: {self.sampler!r} (allowed: {', '.join(SAMPLERS)})")
        for flag, weight in (("--variety-weight", self.variety_weight),
                             ("--distribution-weight", self.distribution_weight)):
            if not weight >= 0:
                raise SasmiError(f"{flag}: {weight:g} (allowed: >= 0)")
        if self.step is not None and not 0 < self.step <= 0.5:
            raise SasmiError(f"--step: {self.step:g} (allowed: above 0, at most 0.5)")
        if self.redraw_scenes and self.sampler != "cmaes":
            raise SasmiError("--redraw-scenes: draws per CMA-ES generation; TPE has none (use --sampler cmaes)")
        if self.searches < 1:
            raise SasmiError(f"--searches: {self.searches} (allowed: >= 1)")
        if self.contenders < 1:
            raise SasmiError(f"--contenders: {self.contenders} (allowed: >= 1)")
        if self.profile_trials < 0:
            raise SasmiError(f"--profile-trials: {self.profile_trials} (allowed: >= 0)")
        if self.refine_steps < 0:
            raise SasmiError(f"--refine-steps: {self.refine_steps} (allowed: >= 0)")
        for flag, count in (("--chips", self.chips), ("--final-chips", self.final_chips)):
            if count < 8:
                raise SasmiError(f"{flag}: {count} (allowed: >= 8; medians of fewer renders move with every draw)")
        return self

    def weights(self) -> Weights:
        return Weights(phi=self.phi_weight, distribution=self.distribution_weight, variety=self.variety_weight,
                       spread_correction=self.spread_correction)

    def identity(self) -> dict:
        """What a rerun must share to continue the study: everything but the budget, where trials run and what
        follows the search."""
        kept = {k: v for k, v in asdict(self).items()
                if k not in ("minutes", "trials", "workers", "scheduler", "contenders", "profile_trials",
                             "refine_steps")}
        return {**kept, "search_scenes": "own"}  # each search its own draw (searches once raced over one)


def render_chips(preset: Preset, count: int, cfg: CalibrateConfig, seed: int, first: int = 0) -> np.ndarray:
    """(count, S, S) float32 in [0, 1], rounded to 8 bits as the real chips' PNGs are: scenes first, first + 1, ...
    of `seed`."""
    from sasmi.renderset.order import render_grouped

    images = render_grouped([preset.sample(seed, i) for i in range(first, first + count)], cfg.size, cfg.spp)
    return (np.round(np.clip(images, 0, 1) * 255) / 255).astype(np.float32)


def _check_record(out: Path, record: dict) -> None:
    path = out / "calibrate.json"
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, ValueError):
            raise SasmiError(f"{path}: unreadable; remove {out} or choose another --out") from None
        # a study begun before --step, --searches and --redraw-scenes existed was one search at Optuna's own first
        # step, every trial on the same scenes; searches begun before each had its own scenes raced over one draw
        kept = {"step": None, "searches": 1, "redraw_scenes": False, **old.get("identity", {})}
        kept.setdefault("search_scenes", "own" if kept["searches"] == 1 else "shared")
        if kept != record["identity"]:
            changed = sorted(k for k in record["identity"] if kept.get(k) != record["identity"][k])
            raise SasmiError(f"{out}: holds a calibration with other settings ({', '.join(changed)}); rerun with "
                             "its settings to continue it, or choose another --out")
    write_text(path, json.dumps(record, indent=2) + "\n")


def trial_score(raw: dict, preset_path: Path | None, real: RealChips, cfg: CalibrateConfig, encoder,
                first: int = 0) -> dict:
    """One trial: the candidate preset's `cfg.chips` renders (scenes `first`, ... of `cfg.seed`) scored, or the rule
    one of its draws broke."""
    try:
        candidate = Preset.from_dict(raw, path=preset_path)
        images = render_chips(candidate, cfg.chips, cfg, cfg.seed, first)
    except SasmiError as e:  # knobs that break a cross-field rule in some scene (a buried target, ...)
        return {"objective": FAILED, "invalid": str(e)}
    s = score(images, real, encoder, cfg.weights())
    return {k: s[k] for k in ("objective", "statistics", "distribution", "phi_ratio", "recall", "passed")}


@functools.lru_cache(maxsize=2)
def _worker_encoder(phi: str | None):
    from sasmi.eval.features import as_encoder

    return as_encoder(phi)


def _on_worker(raw: dict, preset_path: Path | None, real: RealChips, cfg: CalibrateConfig, phi: str | None,
               threads: int | None, first: int) -> dict:
    """`trial_score` on a Dask worker: its own φ (loaded once per process) and its share of the cores."""
    import drjit
    import torch

    torch.set_num_threads(1)
    if threads:
        drjit.set_thread_count(threads)
    return trial_score(raw, preset_path, real, cfg, _worker_encoder(phi), first)


@contextlib.contextmanager
def trial_runner(cfg: CalibrateConfig, preset: Preset, real: RealChips, encoder, phi) -> Iterator[tuple]:
    """(run, width): run(raws[, seed][, firsts]) -> their scores (each raw's scenes from its first, default 0),
    `width` trials at a time: here, or on a Dask cluster (--scheduler, or --workers local processes, each with its
    share of the cores)."""
    if cfg.workers == 1 and not cfg.scheduler:
        yield (lambda raws, seed=cfg.seed, firsts=None: [
            trial_score(raw, preset.path, real, replace(cfg, seed=seed), encoder, first)
            for raw, first in zip(raws, firsts or [0] * len(raws))]), 1
        return
    from sasmi.renderset.cluster import dask_client
    from sasmi.renderset.threads import local_threads

    if phi is not None and not isinstance(phi, (str, os.PathLike)):
        raise SasmiError("--workers: a φ given as a module cannot travel to the workers; pass its run or file")
    threads = None if cfg.scheduler else local_threads(cfg.workers)
    light = replace(real, images=real.images[:0])  # the workers need the statistics and φ, not the chips
    with dask_client(cfg.scheduler, cfg.workers) as client:
        shared = client.scatter(light, broadcast=True, hash=False)
        path = None if phi is None else str(phi)

        def run(raws: list[dict], seed: int = cfg.seed, firsts: list[int] | None = None) -> list[dict]:
            return client.gather([client.submit(_on_worker, raw, preset.path, shared, replace(cfg, seed=seed), path,
                                                threads, first, pure=False)
                                  for raw, first in zip(raws, firsts or [0] * len(raws))])

        yield run, max(1, sum(client.nthreads().values()))


def calibrate(real_folder: str | Path, start: str | Path, cfg: CalibrateConfig, out: str | Path,
              phi=None, progress: bool = True) -> Path:
    """Search the knobs for `cfg.minutes` (all runs together), then write RUN/preset.toml and RUN/report.md."""
    from tqdm import tqdm

    from sasmi.eval.features import as_encoder, describe_phi
    from sasmi.gan.loop import StopSignals
    from sasmi.images import FolderLock
    from sasmi.realism.calibration_pins import what_the_chips_pin
    from sasmi.realism.calibration_report import write_report

    cfg = cfg.validate()
    out = Path(out)
    preset = load_preset(start)
    x0 = start_values(preset.raw, cfg.params)  # a knob the preset cannot take (a kind it lacks) fails here
    encoder = as_encoder(phi)
    # read before anything is written: a bad folder leaves no RUN
    real = real_chips(real_folder, encoder, cfg.chips, cfg.size, cfg.seed)
    check_room(out, ROOM, "a calibration's study and report")
    lock = FolderLock(out, "running sasmi calibrate")
    try:
        record = {"real": str(Path(real_folder).resolve()), "start": str(preset.path.resolve()),
                  "phi": describe_phi(encoder), "identity": {**cfg.identity(), "params": list(cfg.params),
                                                             "real": str(Path(real_folder).resolve()),
                                                             "start": str(preset.path.resolve()),
                                                             "statistics": list(real.checked),
                                                             "found_tolerance": real.tolerances["targets_found"].high}}
        _check_record(out, record)
        studies = open_studies(out, cfg, x0)
        stop = StopSignals()
        budget = cfg.minutes * 60
        with trial_runner(cfg, preset, real, encoder, phi) as (run, width), \
                tqdm(total=round(budget), unit="s", desc="calibrate", disable=not progress or None) as bar:
            with full_disk_named(out):
                for search, study in enumerate(studies):  # the trials a killed run asked: scored as asked
                    run_batch(study, search, preset, cfg, x0, run, 0)
            while True:
                spent, done = searched_seconds(studies), sum(asked(s) for s in studies)
                bar.n = min(round(spent), round(budget))
                # best_value reads the best trial alone; best_trials reads every trial, about a second a batch once
                # the study holds thousands, outside the search time counted
                bar.set_postfix(trials=done, best=f"{min(lowest(s) for s in studies):.3g}")
                bar.refresh()
                search = next_search(studies, cfg)
                if search is None:
                    break
                if stop.signal:
                    raise Stopped(stop.signal, f"stopped after {done} trials; rerun the same command to "
                                               f"continue ({out}/study.db keeps every trial)")
                with full_disk_named(out):
                    width_now = width if cfg.trials is None else min(width, cfg.trials - done)
                    run_batch(studies[search], search, preset, cfg, x0, run, width_now)
            stop.restore()
            bar.close()
            final = replace(cfg, seed=cfg.seed + 1)
            judged = tqdm(unit="trial", desc="choose and judge the calibrated trial", disable=not progress or None)

            def objectives(settings: list[dict], seed: int) -> list[float]:  # on the scenes of `seed`
                scores = run([apply(preset.raw, values) for values in settings], seed)
                judged.update(len(settings))
                return [s["objective"] for s in scores]
            # other draws of the search's scenes: some to choose the calibrated trial, others to judge its knobs
            draws = [cfg.seed + 2 + k for k in range(2 * FRESH_DRAWS)]
            each = [calibrated_trial(study, preset, cfg, final, objectives, draws[:FRESH_DRAWS]) for study in studies]
            shown = {"start": report_renders(preset, real, encoder, cfg, final)}
            each_shown = [report_renders(Preset.from_dict(raw, path=preset.path), real, encoder, cfg, final)
                          for raw, _ in each]
            search = min(range(len(studies)), key=lambda i: (each_shown[i][1]["two_sample"], i))  # told least
            (best_raw, best), shown["calibrated"] = each[search], each_shown[search]
            trials = [(t.value, t.params) for t in studies[search].trials if t.value is not None]

            def kept_objectives(settings: list[dict], seed: int = scene_seed(cfg, search)) -> list[float]:
                return objectives(settings, seed)  # by default on the kept search's own scenes
            pins, together = what_the_chips_pin(best.params, trials, kept_objectives, draws[FRESH_DRAWS:],
                                                cfg.profile_trials, cfg.seed)
            judged.close()
        refinement = None
        if cfg.refine_steps:
            best_raw, shown["calibrated"], refinement = refine(best_raw, preset, real, encoder, cfg, final,
                                                                shown["calibrated"], progress)
        judgement = [(trial.number, score) for (_, trial), (_, score) in zip(each, each_shown)]
        raws = [best_raw if i == search else raw for i, (raw, _) in enumerate(each)]
        write_report(out, record, cfg, preset, raws, real, studies, search, judgement, shown, pins, together,
                     refinement)
    finally:
        lock.release()
    return out


def report_renders(preset: Preset, real: RealChips, encoder, cfg: CalibrateConfig, final: CalibrateConfig) -> tuple:
    """(renders, score): `cfg.final_chips` renders of scenes no trial rendered, scored with the report's figures."""
    images = render_chips(preset, cfg.final_chips, final, final.seed)
    return images, final_score(images, real, encoder, cfg.weights(), cfg.seed)


def refine(raw: dict, start: Preset, real: RealChips, encoder, cfg: CalibrateConfig, final: CalibrateConfig,
           calibrated: tuple, progress: bool) -> tuple[dict, tuple, dict]:
    """`cfg.refine_steps` of `sasmi fit-scene` (its φ distribution loss) from the calibrated preset `raw`:
    (the preset, its report renders and score, what the refinement did), the refined preset only where it
    lowers the objective of `calibrated` ((renders, score) of `raw`) on the same scenes."""
    from sasmi.realism.fit_scene import FitConfig, fit_scene, scaled_preset

    candidate = Preset.from_dict(raw, path=start.path)
    fit_cfg = FitConfig(params=REFINED, steps=cfg.refine_steps, size=cfg.size, seed=cfg.seed)
    if not any(candidate.sample(cfg.seed, i).seafloor.has_relief for i in range(fit_cfg.scenes)):
        fit_cfg = replace(fit_cfg, params=REFINED[1:])  # a flat floor has no relief to scale
    fit = fit_scene(candidate, encoder, real.phi, fit_cfg, progress)
    note = {"steps": cfg.refine_steps, "scales": fit.scales, "before": calibrated[1]["objective"], "after": None}
    refined = scaled_preset(candidate, fit.scales)
    try:
        images = render_chips(Preset.from_dict(refined, path=start.path), cfg.final_chips, final, final.seed)
    except SasmiError as e:  # a scaled relief or altitude that breaks a rule in some scene
        return raw, calibrated, {**note, "kept": False, "invalid": str(e)}
    score = final_score(images, real, encoder, cfg.weights(), cfg.seed)
    note.update(after=score["objective"], kept=score["objective"] < note["before"])
    return (refined, (images, score), note) if note["kept"] else (raw, calibrated, note)
