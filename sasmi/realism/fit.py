"""`sasmi fit`: from real chips to a realism report in one resumable command, within a time budget.

Stages, each into its own folder of RUN (ordinary folders the other commands accept):
    phi         the φ autoencoder on the φ chips                 (sasmi train autoencoder)
    renders     the preset rendered at the training size        (sasmi render)
    on_floors   their targets on real seafloor chips (sasmi.realism.floors; the stage `floors`, skipped with --no-floors)
    sasgan      the SAS GAN, trained until its share of time ends (sasmi train sasgan)
    translated  on_floors (or the renders) through the generator (sasmi translate)
    report      φ-FID/KID/P-R, statistics, target preservation   (sasmi evaluate)

RUN/fit.json records the plan, the seconds each stage has used and which stages are
done; rerunning the same command continues where a killed run stopped (the training
stages resume from their last checkpoint) and a larger --minutes trains on.
"""
from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from sasmi.errors import SasmiError
from sasmi.gan.recipes import DEFAULT as DEFAULT_RECIPE, load_recipe
from sasmi.images import list_images, write_text

STAGES = ("phi", "renders", "on_floors", "sasgan", "translated", "report")  # each writes RUN/<stage>
# shares of --minutes for the two trainings; rendering, translating and the report take what they take
SHARE = {"phi": 0.2, "sasgan": 0.7}
MIN_CHUNK_SECONDS = 60  # less GAN time than this left in the budget is not worth a chunk
FIRST_CHUNK = 20  # steps trained before the speed is known


@dataclass(frozen=True)
class FitPlan:
    real: str  # real target chips the SAS GAN learns from
    out: str
    phi_real: str  # chips φ learns from (targets and seafloor: φ must know both)
    validation: str  # real chips the report compares with; never seen by φ or the GAN when they differ
    minutes: float = 60.0
    size: int = 128
    preset: str = "cylinder_chip"
    count: int = 400  # chips rendered: the GAN's render set, and the set the report translates
    seed: int = 0
    recipe: str = DEFAULT_RECIPE  # SAS GAN settings: a shipped recipe's name (gan/recipes/) or a TOML file
    phi: str = ""  # an existing autoencoder run to use instead of training RUN/phi
    floors: str | None = None  # real seafloor chips the renders' targets are laid on (RUN/on_floors);
    #                            "" keeps the renders' own floors; None: phi_real's seafloor/ when it has one

    def identity(self) -> dict:
        """What a rerun must share with the run it continues (the budget may grow)."""
        d = asdict(self)
        d.pop("minutes")
        if not d["floors"]:
            d.pop("floors")  # a fit.json without the key (no floors) matches a --no-floors rerun
        return d

    @property
    def stages(self) -> tuple[str, ...]:
        return STAGES if self.floors else tuple(s for s in STAGES if s != "on_floors")

    @property
    def gan_input(self) -> Path:
        """The set the SAS GAN learns from and translates: the renders, or the renders on real floors."""
        return Path(self.out) / ("on_floors" if self.floors else "renders")


def _log(stage: str, message: str, plan: FitPlan, used: float) -> None:
    left = max(plan.minutes * 60 - used, 0) / 60
    print(f"sasmi fit: [{plan.stages.index(stage) + 1}/{len(plan.stages)} {stage}] {message} ({left:.0f} min of the budget left)",
          file=sys.stderr, flush=True)


class State:
    """RUN/fit.json: the plan, seconds used per stage, stages done; rewritten atomically after each change."""

    def __init__(self, plan: FitPlan):
        self.path = Path(plan.out) / "fit.json"
        self.plan = plan
        self.seconds: dict[str, float] = {}
        self.done: list[str] = []
        if self.path.is_file():
            try:
                saved = json.loads(self.path.read_text())
            except (OSError, json.JSONDecodeError) as e:
                raise SasmiError(f"{self.path}: unreadable ({e}); choose another --out") from None
            if saved.get("plan") != plan.identity():
                raise SasmiError(f"{plan.out}: holds a `sasmi fit` run with other settings; choose another --out "
                                 f"(only --minutes may change)")
            self.seconds, self.done = saved.get("seconds", {}), saved.get("done", [])
        elif Path(plan.out).exists() and any(p.name != ".lock" for p in Path(plan.out).iterdir()):
            raise SasmiError(f"--out {plan.out}: exists and is not a `sasmi fit` run; choose another --out")

    @property
    def used(self) -> float:
        return sum(self.seconds.values())

    def add(self, stage: str, seconds: float, done: bool = False) -> None:
        self.seconds[stage] = self.seconds.get(stage, 0.0) + seconds
        if done and stage not in self.done:
            self.done.append(stage)
        self.save()

    def save(self) -> None:
        write_text(self.path, json.dumps({"plan": self.plan.identity(), "minutes": self.plan.minutes,
                                          "seconds": self.seconds, "done": self.done}, indent=2) + "\n")


def train_for(kind, overrides: dict, out: Path, inputs: dict, device, seconds: float, stage: str,
              state: State) -> int:
    """Train `kind` in chunks until `seconds` more have passed; returns the step reached.

    Each chunk is an ordinary resumed run (resume is exact), so a kill loses at most one chunk.
    """
    from sasmi.gan.loop import resolve_config, train

    from sasmi.gan.run import read_run

    deadline = time.monotonic() + seconds
    last = out / "checkpoints" / "last.pt"
    step = read_run(out, kind.name).step if last.is_file() else 0  # a killed run's step; later chunks know theirs
    chunk, per_step = FIRST_CHUNK, None
    while True:
        left = deadline - time.monotonic()
        if per_step is not None:
            if left < 2 * per_step:
                break
            chunk = max(1, min(int(left * 0.95 / per_step), 500))  # a progress line at least every 500 steps
        resume = last.is_file()
        cfg = resolve_config(kind, out, {"steps": step + chunk} if resume else {**overrides, "steps": chunk}, resume)
        started = time.monotonic()
        done = train(kind, cfg, out, inputs, device, resume)
        spent = time.monotonic() - started
        per_step = spent / max(done.step - done.start, 1)
        step = done.step
        state.add(stage, spent)
        _log(stage, f"step {step}, {1 / per_step:.2f} steps/s", state.plan, state.used)
    return step


def fit(plan: FitPlan, device) -> Path:
    """Run every stage not yet done; returns RUN/report/report.md."""
    from sasmi.preprocess import check_size
    from sasmi.scene.preset import load_preset

    check_size(plan.size)
    preset = load_preset(plan.preset)  # a bad preset and a bad recipe fail before anything is written
    gan_settings = load_recipe(plan.recipe)
    folders = {"--real": plan.real, "--phi-real": plan.phi_real, "--validation": plan.validation}
    if plan.floors:
        folders["--floors"] = plan.floors
    for flag, folder in folders.items():
        if not list_images(folder):
            raise SasmiError(f"{flag} {folder}: no image (png, jpg, tif, tiff, npy) in it")
    from sasmi.images import FolderLock

    state = State(plan)
    out = Path(plan.out)
    lock = FolderLock(out, "running sasmi fit")  # released when the process ends: one fit at a time in RUN
    try:
        state.save()  # before any stage writes: a run killed in its first stage is still this fit's, to resume
        return _stages(plan, state, preset, gan_settings, device)
    finally:
        lock.release()


def _stages(plan: FitPlan, state: State, preset, gan_settings: dict, device) -> Path:
    """Every stage of `fit` not yet done."""
    from sasmi.gan.kinds.autoencoder import AUTOENCODER
    from sasmi.gan.kinds.sasgan import SASGAN

    out = Path(plan.out)
    budget = plan.minutes * 60

    def stage_time(stage: str) -> float:
        return SHARE[stage] * budget - state.seconds.get(stage, 0.0)

    phi = Path(plan.phi) if plan.phi else out / "phi"
    if plan.phi:
        from sasmi.gan.autoencoder import load_encoder

        load_encoder(phi)  # a bad --phi fails here, not after the renders
    elif "phi" not in state.done:  # trained once: a φ that moved under a trained GAN would void its φ loss
        _log("phi", f"training on {plan.phi_real}", plan, state.used)
        train_for(AUTOENCODER, {"size": plan.size, "seed": plan.seed}, out / "phi", {"real": plan.phi_real},
                  device, stage_time("phi"), "phi", state)
        state.add("phi", 0.0, done=True)

    if "renders" not in state.done:
        from sasmi.renderset.write import RenderJob, render_set

        _log("renders", f"{plan.count} chips of {preset.path}", plan, state.used)
        started = time.monotonic()
        render_set(RenderJob(preset=preset, out=out / "renders", count=plan.count, seed=plan.seed, size=plan.size))
        state.add("renders", time.monotonic() - started, done=True)

    if plan.floors and "on_floors" not in state.done:
        from sasmi.realism.floors import onto_real_floors

        _log("on_floors", f"the renders' targets on floors of {plan.floors}", plan, state.used)
        started = time.monotonic()
        onto_real_floors(out / "renders", plan.floors, plan.real, plan.gan_input, plan.size, plan.seed)
        state.add("on_floors", time.monotonic() - started, done=True)

    if "sasgan" in state.done and stage_time("sasgan") <= MIN_CHUNK_SECONDS:
        # a rerun, perhaps with a budget raised too little to train on: say so, and what would
        least = (state.seconds.get("sasgan", 0.0) + MIN_CHUNK_SECONDS) / SHARE["sasgan"] / 60
        _log("sasgan", f"trained; --minutes {math.floor(least * 10) / 10 + 0.1:g} or more trains on", plan, state.used)
    else:
        _log("sasgan", f"training on {plan.real} and {plan.gan_input.name}", plan, state.used)
        train_for(SASGAN, {**gan_settings, "size": plan.size, "seed": plan.seed}, out / "sasgan",
                  {"real": plan.real, "renders": plan.gan_input, "phi": phi}, device, stage_time("sasgan"),
                  "sasgan", state)
        state.add("sasgan", 0.0, done=True)
        state.done = [s for s in state.done if s not in ("translated", "report")]  # a longer GAN run: redo these

    if "translated" not in state.done:
        from sasmi.gan.generator import load_generator
        from sasmi.gan.translate import translate_folder

        _log("translated", f"{plan.gan_input.name} through the generator", plan, state.used)
        started = time.monotonic()
        translate_folder(load_generator(out / "sasgan", device), plan.gan_input, out / "translated")
        state.add("translated", time.monotonic() - started, done=True)

    path = out / "report" / "report.md"
    if "report" not in state.done or not path.is_file():
        _log("report", f"against {plan.validation}", plan, state.used)
        started = time.monotonic()
        path = report(plan, device)
        state.add("report", time.monotonic() - started, done=True)
    return path


def report(plan: FitPlan, device) -> Path:
    import functools

    from sasmi.chips.stats import median_statistics
    from sasmi.eval import report as rep
    from sasmi.eval.features import as_encoder
    from sasmi.eval.evaluate import StderrLog, evaluate_folders

    out = Path(plan.out)
    encoder = as_encoder(Path(plan.phi) if plan.phi else out / "phi", device)
    inputs = {"validation": plan.validation, "real (GAN)": plan.real, "phi real": plan.phi_real}
    sets = {"sasgan": out / "translated", "renders": out / "renders"}
    if plan.floors:
        sets["on_floors"] = plan.gan_input  # the GAN's own input: what it added is sasgan against this row
    if Path(plan.validation).resolve() != Path(plan.real).resolve():
        # the real chips the GAN learned from, as one more set: what a generator that reproduced them
        # exactly would reach on validation. Where validation's scenes differ from train's, no
        # recipe learning from train alone can be expected to come closer (docs/gan.md)
        sets["train_real"] = Path(plan.real)
        note = ("\n\nThe row `train_real` is the GAN's own real chips (`--real`) against the validation chips: "
                "what a generator that reproduced them exactly would reach.")
    else:
        note = ("\n\n> **Warning.** The report compares with the chips the GAN trained on: its figures are "
                "optimistic. Pass `--validation` (see `sasmi split`).")
    result = rep.Report({"inputs": inputs, "plan": asdict(plan)}, (rep.Section(
        "Inputs", "\n".join(f"- {k}: `{v}`" for k, v in inputs.items()) + note),))
    result += evaluate_folders(plan.validation, sets, encoder,
                               out / "report", log=StderrLog(f"sasmi fit: [{len(plan.stages)}/{len(plan.stages)} report]"),
                               statistics=functools.partial(median_statistics, size=plan.size))
    return rep.write_report(out / "report", result, title="sasmi fit: realism report")


def with_defaults(plan: FitPlan) -> FitPlan:
    phi_real = plan.phi_real or plan.real
    return replace(plan, phi_real=phi_real, validation=plan.validation or default_validation(plan.real),
                   floors=default_floors(phi_real) if plan.floors is None else plan.floors)


def default_validation(real: str) -> str:
    """`sasmi split`'s validation/CATEGORY beside a --real of train/CATEGORY, else --real itself: a report
    on the chips the GAN learned from flatters it, and a command may name only train folders."""
    real_path = Path(real)
    beside = real_path.parent.parent / "validation" / real_path.name
    if real_path.parent.name == "train" and beside.is_dir() and list_images(beside):
        return str(beside)
    return real


def default_floors(phi_real: str) -> str:
    """The seafloor chips beside the targets that φ learns from (`sasmi split`'s train/seafloor/), or ""."""
    seafloor = Path(phi_real) / "seafloor"
    return str(seafloor) if seafloor.is_dir() and list_images(seafloor) else ""
