"""A run folder: checkpoints that carry their own config, and one loader for every run kind.

RUN/checkpoints/last.pt and best.pt each hold (as nanoGPT's checkpoints do) everything
needed to rebuild and continue the run: its kind, its resolved config, the fingerprints
of its input folders, the step, the best score so far, every model, optimiser and random
stream. They contain tensors and plain types only and load with weights_only=True.
RUN/config.json is a human-readable copy of the config; RUN/tb/ and RUN/samples/ are logs.

best.pt: the checkpoint at a step that is a multiple of checkpoint_every (and at least
best_from) whose score, averaged over the checkpoint_every steps before it, is the lowest
so far. Both the running average and the best score are in every checkpoint, so the step
best.pt holds does not depend on where a run was interrupted and resumed.

This module knows no model: the model modules rebuild their nets from `Saved.config`.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import MISSING, asdict, dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, Callable

import torch
from tqdm import tqdm

from sasmi.errors import SasmiError
from sasmi.images import write_gray, write_text, write_torch
from sasmi.limits import TRAIN_MAX_SIZE, setting_range
from sasmi.preprocess import signed_to_unit

# the checkpoint layout this sasmi writes and reads; a file without the key is of format 1. Raise it
# when a change to the layout would make an older sasmi misread a newer file
FORMAT = 1


def provenance() -> dict:
    """What made a run: versions, the source commit (when run from a git checkout) and the command line."""
    import subprocess
    import sys

    from sasmi import __version__

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).resolve().parent, capture_output=True,
                                text=True, timeout=5).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    return {"sasmi": __version__, "torch": torch.__version__, "git_commit": commit, "command": sys.argv}


def check_number(name: str, value, high: float | None = None) -> None:
    """A SasmiError naming `name` unless `value` is a finite number in its range in sasmi.limits
    (`high`: a tighter upper bound that depends on other settings)."""
    allowed = setting_range(name)
    if high is not None:
        allowed = replace(allowed, hi=min(high, allowed.hi))
    integer = allowed.kind is int
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not is_number or integer and math.isfinite(value) and not float(value).is_integer():
        raise SasmiError(f"{name}: {value!r} is not {'an integer' if integer else 'a number'}")
    allowed.check(value, name)


@dataclass(frozen=True)
class RunConfig:
    """What every run kind shares. Subclasses add their models' and losses' settings."""
    steps: int = 2000  # target total of updates (raise it and --resume to train on)
    size: int = 128  # images are S×S, S a multiple of 16; the real chips are 128
    batch: int = 4
    seed: int = 0  # weights, data order, augmentation and noise all follow from it
    lr: float = 1e-3  # Reed et al.'s Adam rate
    betas: tuple[float, float] = (0.9, 0.999)  # Adam's defaults
    log_every: int = 10  # steps between TensorBoard scalars
    sample_every: int = 250  # steps between sample grids
    checkpoint_every: int = 250  # steps between last.pt writes; also best.pt's interval
    best_from: int = 0  # best.pt is only chosen at or after this step
    # bf16 autocast on CUDA (a CPU always trains in float32): off, since at batch 4 it is slower
    # than float32 on an H200 and an H100 (docs/gan.md, *GPU and CPU notes*)
    amp: bool = False

    def validate(self) -> "RunConfig":
        """Self, or a SasmiError naming the flag and the allowed range."""
        check_number("--steps", self.steps)
        check_number("--size", self.size, high=TRAIN_MAX_SIZE)
        check_number("--batch", self.batch)
        check_number("--seed", self.seed)
        check_number("--lr", self.lr)
        if not (isinstance(self.betas, tuple) and len(self.betas) == 2):
            raise SasmiError(f"--betas {self.betas}: expected two numbers")
        for beta in self.betas:
            check_number("--betas", beta)
        check_number("--checkpoint-every", self.checkpoint_every)
        for flag in ("log_every", "sample_every"):
            check_number(flag, getattr(self, flag))
        check_number("best_from", self.best_from)
        return self


def config_from_dict(cls, data: dict, source: str):
    """A (nested) config dataclass from its asdict() form; missing fields keep their defaults.
    A value of the wrong type is a SasmiError naming `source` and the field."""
    try:
        return _build(cls, data)
    except (TypeError, ValueError, AttributeError) as e:
        raise SasmiError(f"{source}: its {cls.__name__} cannot be rebuilt ({e})") from None


def _build(cls, data: dict, prefix: str = ""):
    kwargs = {}
    for f in fields(cls):
        if f.name not in data:
            continue
        default = f.default if f.default is not MISSING else f.default_factory()
        value = data[f.name]
        if is_dataclass(default):
            value = _build(type(default), value, f"{prefix}{f.name}.")
        elif isinstance(default, tuple):
            value = tuple(value)
        elif not _same_kind(value, default):
            raise TypeError(f"{prefix}{f.name} = {value!r}: expected {type(default).__name__}")
        kwargs[f.name] = value
    return cls(**kwargs)


def _same_kind(value, default) -> bool:
    """A setting's value has its default's type (an integer may stand for a float; a bool for nothing else)."""
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(value, bool) and isinstance(default, bool)
    if isinstance(default, float):
        return isinstance(value, (int, float))
    if isinstance(default, (int, str)):
        return isinstance(value, type(default))
    return True


def fingerprint(paths: list[Path], root: Path) -> str:
    """A short hash of a file list (relative names and sizes): which images a run trained on."""
    h = hashlib.sha256()
    for p in sorted(paths):
        h.update(f"{p.relative_to(root)}\0{p.stat().st_size}\n".encode())
    return h.hexdigest()[:16]


def file_fingerprint(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


# ---------------------------------------------------------------- reading

@dataclass
class Saved:
    """One checkpoint as read from disk (CPU tensors)."""
    path: Path
    kind: str
    config: dict  # asdict() of the run's config
    step: int
    state: dict  # name → state_dict of each model, optimiser and stream
    extra: dict  # everything else the loop stored (inputs, best, rng)


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0][:160] if text else ''}"


def read_checkpoint(path: Path, kind: str) -> Saved:
    """A checkpoint of a `kind` run, or one SasmiError naming the file."""
    if not path.is_file():
        raise SasmiError(f"{path}: no such checkpoint")
    if path.stat().st_size == 0:
        raise SasmiError(f"{path}: empty file, not a checkpoint")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated, random bytes, a pickle carrying code: all one line
        why = ("refused: it names Python objects other than tensors and plain types, which could run code"
               if "GLOBAL" in str(e) else f"truncated or not a torch file; {type(e).__name__}")
        raise SasmiError(f"{path}: not a readable checkpoint ({why})") from None
    if not isinstance(ckpt, dict) or not isinstance(ckpt.get("state"), dict) or "step" not in ckpt:
        raise SasmiError(f"{path}: not a sasmi training checkpoint")
    if "config" not in ckpt:  # a checkpoint that carries no config: the run's config.json has it
        try:
            saved = json.loads((path.parent.parent / "config.json").read_text())
            ckpt["kind"], ckpt["config"] = saved["kind"], saved["config"]
        except (OSError, ValueError, KeyError, TypeError):
            raise SasmiError(f"{path}: carries no config and its run has no readable config.json") from None
    if ckpt.get("format", 1) != FORMAT:
        raise SasmiError(f"{path}: checkpoint format {ckpt.get('format')!r}; this sasmi {_version()} reads format "
                         f"{FORMAT} (written by {ckpt.get('sasmi', 'another version')}): use that version, or retrain")
    if ckpt.get("kind") != kind:
        raise SasmiError(f"{path}: is a {ckpt.get('kind')!r} run, expected a {kind!r} run")
    extra = {k: v for k, v in ckpt.items() if k not in ("kind", "config", "step", "state", "format", "sasmi")}
    return Saved(path, kind, ckpt["config"], int(ckpt["step"]), ckpt["state"], extra)


def _version() -> str:
    from sasmi import __version__

    return __version__


def read_run(run_dir: str | os.PathLike, kind: str, which: str = "last") -> Saved:
    """checkpoints/{which}.pt of a `kind` run folder, `which` being "last", "best" or a
    checkpoint file's path; a `run_dir` that is a file (a checkpoint, or weights that
    `export_weights` wrote) is read as it is. A run shorter than one checkpoint interval
    has no best.pt yet; `which="best"` then reads last.pt."""
    run_dir = Path(run_dir)
    if which not in ("last", "best"):
        return read_checkpoint(Path(which), kind)
    if run_dir.is_file():
        return read_checkpoint(run_dir, kind)
    if not (run_dir / "checkpoints" / "last.pt").is_file():
        raise SasmiError(f"{run_dir}: not a training run (no checkpoints/last.pt)")
    path = run_dir / "checkpoints" / f"{which}.pt"
    if which == "best" and not path.exists():
        path = run_dir / "checkpoints" / "last.pt"
    return read_checkpoint(path, kind)


def load_weights(module: torch.nn.Module, saved: Saved, name: str, prefix: str = "") -> None:
    """saved.state[name] (its `prefix` entries, prefix removed) into `module`, or a SasmiError
    naming the file (weights of another architecture)."""
    try:
        state = saved.state[name]
        if prefix:
            state = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
        module.load_state_dict(state)
    except (KeyError, RuntimeError, TypeError, ValueError, AttributeError) as e:
        raise SasmiError(f"{saved.path}: its {name} weights do not fit the network its config describes "
                         f"({_one_line(e)})") from None


# ---------------------------------------------------------------- writing

def image_grid(rows: list[torch.Tensor], pad: int = 2) -> torch.Tensor:
    """Rows of (n, 1, S, S) in [-1, 1] → one (1, H, W) image in [0, 1] on white."""
    n, _, s, _ = rows[0].shape
    grid = torch.ones(1, len(rows) * (s + pad) + pad, n * (s + pad) + pad)
    for r, row in enumerate(rows):
        for c, image in enumerate(signed_to_unit(row.detach().float().cpu())):
            top, left = pad + r * (s + pad), pad + c * (s + pad)
            grid[:, top:top + s, left:left + s] = image
    return grid


class RunFolder:
    """The run folder and everything a step hands to it: logs, samples, checkpoints.

    `state` maps names to objects with state_dict/load_state_dict (models, optimisers,
    batch streams, noise); all of them go into each checkpoint. `inputs` maps an input's
    flag name to (folder, fingerprint); a resume onto other data is refused. Across
    processes only the `main` one writes; the others read a resumed state and keep count.
    """

    def __init__(self, kind: str, cfg: RunConfig, out: str | os.PathLike, inputs: dict[str, tuple[str, str]],
                 resume: bool, state: dict[str, Any], samples: Callable[[], list[torch.Tensor]], main: bool = True):
        self.kind, self.cfg, self.out, self.state, self.samples = kind, cfg, Path(out), state, samples
        self.main = main
        self.inputs = {k: {"path": str(Path(p).resolve()), "fingerprint": f} for k, (p, f) in inputs.items()}
        self.step = self.saved_step = 0
        self.best = {"score": math.inf, "step": None}
        self.interval = [0.0, 0]  # score sum and count since the last multiple of checkpoint_every
        if resume:
            self._load()
        self.writer = None
        self.bar = tqdm(total=cfg.steps, initial=self.step, unit="step", desc=f"{kind} {self.out.name}",
                        dynamic_ncols=True, mininterval=1.0, disable=None if main else True)
        if not main:
            return
        write_text(self.out / "config.json", json.dumps(
            {"kind": kind, "config": asdict(cfg), "inputs": self.inputs, "provenance": provenance()}, indent=2) + "\n")
        if not resume:
            self._save("last")  # so a run that fails at once still has a good state to resume
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(str(self.out / "tb"), purge_step=self.step if resume else None)

    def _load(self) -> None:
        saved = read_checkpoint(self.out / "checkpoints" / "last.pt", self.kind)
        for name, was in saved.extra.get("inputs", {}).items():
            now = self.inputs.get(name)
            if now and was["fingerprint"] != now["fingerprint"]:
                raise SasmiError(f"--{name} {now['path']}: not the data this run was trained on (it trained on "
                                 f"{was['path']}, fingerprint {was['fingerprint']}, now {now['fingerprint']}); "
                                 f"resume with the same data or start a new run")
        for name, obj in self.state.items():
            if isinstance(obj, torch.nn.Module):
                load_weights(obj, saved, name)
            else:
                obj.load_state_dict(saved.state[name])
        torch.set_rng_state(saved.extra["torch_rng"])
        self.step = self.saved_step = saved.step
        self.best, self.interval = dict(saved.extra["best"]), list(saved.extra["interval"])

    def _save(self, which: str) -> None:
        if not self.main:
            return
        for name, obj in self.state.items():
            if isinstance(obj, torch.nn.Module) and not all(torch.isfinite(p).all() for p in obj.parameters()):
                raise SasmiError(f"step {self.step}: {name} weights are not finite; "
                                 f"{self.out}/checkpoints/last.pt keeps the last good state (step {self.saved_step})")
        ckpt = {"format": FORMAT, "sasmi": _version(), "kind": self.kind, "config": asdict(self.cfg),
                "inputs": self.inputs, "step": self.step, "best": self.best, "interval": self.interval, "torch_rng": torch.get_rng_state(),
                "state": {name: obj.state_dict() for name, obj in self.state.items()}}
        write_torch(self.out / "checkpoints" / f"{which}.pt", ckpt)
        if which == "last":
            self.saved_step = self.step

    def log(self, step: int, scalars: dict[str, float], score: float) -> None:
        """Record a finished step; `score` (lower is better) picks best.pt."""
        bad = {k: v for k, v in scalars.items() if not math.isfinite(v)}
        if bad:
            self.close()
            raise SasmiError(f"step {step}: non-finite {', '.join(f'{k} = {v}' for k, v in bad.items())}; stopped; "
                             f"{self.out}/checkpoints/last.pt keeps the last good state (step {self.saved_step})")
        self.step = step
        self.interval = [self.interval[0] + score, self.interval[1] + 1]
        self.bar.update(1)
        if self.writer and step % self.cfg.log_every == 0:
            for k, v in scalars.items():
                self.writer.add_scalar(k, v, step)
            self.bar.set_postfix({k.split("/")[-1]: f"{v:.3g}" for k, v in scalars.items() if k.startswith("loss/")})

    def write_samples(self) -> None:
        if not self.main:
            return
        grid = image_grid(self.samples())
        write_gray(self.out / "samples" / f"step_{self.step:06d}.png", grid[0].numpy())
        self.writer.add_image("samples", grid, self.step)

    def checkpoint(self) -> None:
        """best.pt at multiples of checkpoint_every (see the module doc), then last.pt."""
        if self.step % self.cfg.checkpoint_every == 0:
            score = self.interval[0] / max(self.interval[1], 1)
            self.interval = [0.0, 0]
            if self.writer:
                self.writer.add_scalar("score", score, self.step)
            if self.step >= self.cfg.best_from and score < self.best["score"]:
                self.best = {"score": score, "step": self.step}
                self._save("best")
        self._save("last")

    def close(self) -> None:
        self.bar.close()
        if self.writer:
            self.writer.close()
