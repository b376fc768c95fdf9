"""The one training loop for every run kind (autoencoder, SAS GAN, DCGAN).

A kind (gan/kinds/) is a `Kind`: its config class and a `build` that reads the data,
makes the models and returns a `Phases`: the functions one step runs, in order (as
stylegan2-ada-pytorch's loss phases): `critic_steps` × critic step, one generator step
(for the autoencoder: its one update), then log, samples and checkpoint here.

One step is one generator update; every phase draws its own fresh batches from
resumable streams, so 10 steps + resume + 10 steps equals 20 steps bit for bit.

SIGTERM (a cluster's notice before it kills) and Ctrl-C stop a single-process run after the
step in hand: last.pt is written and `sasmi.errors.Stopped` raised, so a resume continues
exactly. A second signal acts at once, as it would without sasmi.
"""
from __future__ import annotations

import os
import signal
import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import torch

from sasmi.gan import distributed
from sasmi.gan.run import RunConfig, RunFolder, config_from_dict, read_checkpoint
from sasmi.errors import SasmiError, Stopped
from sasmi.images import FolderLock, check_room

Logs = dict[str, float]


@dataclass
class Phases:
    """What a kind hands the loop: its state and the phases of one step."""
    state: dict[str, Any]  # everything with state_dict/load_state_dict that goes into a checkpoint
    inputs: dict[str, tuple[str, str]]  # flag name → (folder, fingerprint): checked on resume
    generator_step: Callable[[], Logs]  # one generator (or autoencoder) update on fresh batches
    samples: Callable[[], list[torch.Tensor]]  # sample-grid rows, each (n, 1, S, S) in [-1, 1]
    score: str  # the log entry whose interval mean picks best.pt (lower is better)
    critic_step: Callable[[], Logs] | None = None  # one critic update on fresh batches
    critic_steps: int = 0  # critic updates per step
    finish: Callable[[Path], None] | None = None  # after the last step (e.g. DCGAN's final samples)


@dataclass(frozen=True)
class Kind:
    """A run kind: the name its run folders record, its config, and how to build it."""
    name: str
    config: type[RunConfig]
    build: Callable[[Any, dict[str, Path], torch.device], Phases]  # (config, inputs, device)


@dataclass(frozen=True)
class Trained:
    out: Path
    start: int  # the step the run started (or resumed) from
    step: int  # the step it reached


def resolve_config(kind: Kind, out: str | os.PathLike, overrides: dict, resume: bool) -> RunConfig:
    """The config a run will use: defaults + overrides, or on resume the config inside last.pt.

    On resume only `steps` may change: the checkpoint was trained with the saved settings.
    """
    out = Path(out)
    last = out / "checkpoints" / "last.pt"
    if not resume:
        if last.exists():
            raise SasmiError(f"{out}: already holds a run; pass --resume to continue it or choose another --out")
        try:
            cfg = replace(kind.config(), **overrides)
        except (TypeError, ValueError) as e:
            raise SasmiError(f"{kind.name}: {e}") from None
        return cfg.validate()
    if not last.is_file():
        raise SasmiError(f"{out}: nothing to resume (no checkpoints/last.pt)")
    saved = config_from_dict(kind.config, read_checkpoint(last, kind.name).config, str(last))
    clashes = [f"{k}={v!r} (run has {getattr(saved, k)!r})" for k, v in overrides.items()
               if k != "steps" and v != getattr(saved, k)]
    if clashes:
        raise SasmiError(f"{out}: cannot resume with changed settings: {', '.join(clashes)}")
    return replace(saved, **{k: v for k, v in overrides.items() if k == "steps"}).validate()


def train(kind: Kind, cfg: RunConfig, out: str | os.PathLike, inputs: dict[str, str | os.PathLike],
          device: torch.device, resume: bool = False) -> Trained:
    """Train (or continue) a `kind` run in `out` up to cfg.steps; see the module doc."""
    # ---- data, models, optimisers (read before anything is written: bad input leaves no folder)
    cfg.validate()
    torch.manual_seed(cfg.seed)  # weight initialisation; every later draw has its own stream
    phases = kind.build(cfg, {k: Path(v) for k, v in inputs.items()}, device)

    # ---- the run folder: a fresh one, or the state of last.pt; one training at a time in it
    world = distributed.world()
    lock = FolderLock(out, "training") if world.main else None
    if lock:  # a checkpoint write that a kill -9 cut short leaves its temporary file; none is ever read
        for stale in (Path(out) / "checkpoints").glob(".*.tmp.pt"):
            stale.unlink(missing_ok=True)
    try:
        if lock:
            kept = sum((Path(out) / "checkpoints" / f"{name}.pt").is_file() for name in ("last", "best"))
            check_room(out, (3 - kept) * checkpoint_bytes(phases.state), f"{kind.name} checkpoints")
        run = RunFolder(kind.name, cfg, out, phases.inputs, resume, phases.state, phases.samples, main=world.main)
    except BaseException:
        if lock:
            lock.release()
        raise
    start = run.step
    # bf16 on CUDA when the config asks (autocast keeps losses, norms and the optimisers in float32)
    precision = torch.autocast(device.type, torch.bfloat16, enabled=cfg.amp and device.type == "cuda")
    stop = StopSignals(enabled=world.size == 1)  # across processes each would stop at its own step
    try:
        for step in range(start + 1, cfg.steps + 1):
            with precision:
                # ---- critic: critic_steps updates, each on fresh real and fake batches
                logs: Logs = {}
                for _ in range(phases.critic_steps):
                    logs = phases.critic_step()
                # ---- generator: one update (the autoencoder's reconstruction step)
                logs |= phases.generator_step()
            # ---- log (the mean over processes), samples, checkpoint (the main process writes)
            logs = distributed.mean_logs(logs)
            run.log(step, logs, score=logs[phases.score])
            if step % cfg.sample_every == 0 or step == cfg.steps:
                run.write_samples()
            if step % cfg.checkpoint_every == 0 or step == cfg.steps or stop.signal:
                run.checkpoint()
            if stop.signal:
                raise Stopped(stop.signal, f"stopped by {signal.Signals(stop.signal).name} after step {step}, saved in "
                                           f"{run.out}/checkpoints/last.pt; rerun the command (sasmi train: with "
                                           f"--resume) to continue")
    finally:
        stop.restore()
        run.close()
        if lock:
            lock.release()
    if phases.finish and run.step == cfg.steps and world.main:
        phases.finish(run.out)
    return Trained(run.out, start, run.step)


def checkpoint_bytes(state: dict[str, Any]) -> int:
    """About the bytes of one checkpoint of `state` once training has begun: every model's tensors and, for
    each optimiser, two moments of each of its parameters (Adam's; they do not exist before the first step)."""
    total = 0
    for value in state.values():
        if isinstance(value, torch.optim.Optimizer):
            total += 2 * sum(p.numel() * p.element_size() for group in value.param_groups for p in group["params"])
        elif isinstance(value, torch.nn.Module):  # the generator's moving average too
            total += sum(t.numel() * t.element_size() for t in value.state_dict().values())
    return total


class StopSignals:
    """Note SIGTERM and SIGINT instead of dying, while a training runs (main thread only: Python takes
    signals there). The first restores the previous handlers, so that a second acts as usual."""

    def __init__(self, enabled: bool = True):
        self.signal = 0
        self.previous = {}
        if enabled and threading.current_thread() is threading.main_thread():
            self.previous = {s: signal.signal(s, self._note) for s in (signal.SIGTERM, signal.SIGINT)}

    def _note(self, signum, frame) -> None:
        self.signal = signum
        self.restore()

    def restore(self) -> None:
        for s, handler in self.previous.items():
            signal.signal(s, handler)
        self.previous = {}
