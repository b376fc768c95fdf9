"""Training: the φ autoencoder, the SAS GAN (render → real, WGAN-GP + φ loss) and the
unconditional DCGAN baseline (same objective, z → image).

A run folder holds config.json (the resolved config and the input folders),
checkpoints/last.pt and best.pt (models, optimisers, step, every random stream;
written atomically and loadable with weights_only=True), tb/ (TensorBoard: losses,
gradient norms, sample grids) and samples/step_NNNNNN.png. `--resume` restores all of
it, so 10 steps + resume + 10 steps equals 20 steps. A non-finite loss stops the run
before anything is saved, so last.pt stays the last good state.

One step is one generator update (the GANs also make n_critic critic updates per step,
each on fresh batches); the autoencoder's step is one update.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import MISSING, asdict, dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Callable

import torch
from tqdm import tqdm

from gan.autoencoder import Autoencoder, AutoencoderConfig, load_encoder
from gan.critic import Critic, CriticConfig
from gan.data import Batches, ImageSet, check_size, to_unit
from gan.dcgan import DCGANConfig, DCGANGenerator, sample
from gan.generator import Generator, GeneratorConfig
from gan.losses import critic_loss, generator_loss, gradient_penalty, phi_loss, reconstruction_loss
from sasmi.errors import SasmiError
from sasmi.images import atomic_path, write_gray, write_text


@dataclass(frozen=True)
class RunConfig:
    steps: int = 5000  # generator updates (target total; raise it and --resume to train on)
    size: int = 256  # images are S×S, S a multiple of 16; real chips are 128
    batch: int = 4  # Reed et al.
    seed: int = 0  # weights, data order, augmentation and noise all follow from it
    lr: float = 1e-3  # Reed et al.'s Adam rate; as stable as 1e-4 for the GANs in our probe (docs/gan.md)
    betas: tuple[float, float] = (0.9, 0.999)  # Adam's defaults
    log_every: int = 10  # steps between TensorBoard scalars
    sample_every: int = 250  # steps between sample grids
    checkpoint_every: int = 250  # steps between last.pt (and best.pt) writes


@dataclass(frozen=True)
class AutoencoderRun(RunConfig):
    batch: int = 8  # reconstruction is cheap; a larger batch steadies the L2 gradient
    autoencoder: AutoencoderConfig = AutoencoderConfig()


@dataclass(frozen=True)
class GanRun(RunConfig):
    betas: tuple[float, float] = (0.5, 0.9)  # WGAN-GP's β2 = 0.9 with DCGAN's β1 = 0.5 (WGAN-GP used 0; not probed)
    n_critic: int = 5  # critic updates per generator update (WGAN-GP)
    gp_weight: float = 10.0  # λ of the gradient penalty (WGAN-GP, Reed et al.)
    critic: CriticConfig = CriticConfig()


@dataclass(frozen=True)
class SasganRun(GanRun):
    generator: GeneratorConfig = GeneratorConfig()
    phi_weight: float = 100.0  # at 10 the adversarial term wins and content is lost (docs/gan.md)
    phi_margin: float = 0.25  # γ: φ(G(render)) may move this fraction of ‖φ(render)‖ for free (docs/gan.md)


@dataclass(frozen=True)
class DcganRun(GanRun):
    dcgan: DCGANConfig = DCGANConfig()
    final_samples: int = 256  # images written to final_samples/ when the run completes


RUN_KINDS = {"autoencoder": AutoencoderRun, "sasgan": SasganRun, "dcgan": DcganRun}


# ---------------------------------------------------------------- configs and run folders

def _from_dict(cls, data: dict):
    kwargs = {}
    for f in fields(cls):
        if f.name not in data:
            continue
        default = f.default if f.default is not MISSING else f.default_factory()
        value = data[f.name]
        if is_dataclass(default):
            value = _from_dict(type(default), value)
        elif isinstance(default, tuple):
            value = tuple(value)
        kwargs[f.name] = value
    return cls(**kwargs)


def _read_config(run_dir: Path, kind: str) -> tuple[RunConfig, dict]:
    try:
        saved = json.loads((run_dir / "config.json").read_text())
    except (OSError, ValueError) as e:
        raise SasmiError(f"{run_dir}: not a training run (cannot read config.json: {e})") from None
    if saved.get("kind") != kind:
        raise SasmiError(f"{run_dir}: is a {saved.get('kind')!r} run, expected a {kind!r} run")
    return _from_dict(RUN_KINDS[kind], saved["config"]), saved


def read_run(run_dir: str | os.PathLike, kind: str, checkpoint: str = "last") -> tuple[RunConfig, dict]:
    """The config and a checkpoint of a finished or running run (loaded on the CPU)."""
    run_dir = Path(run_dir)
    cfg, _ = _read_config(run_dir, kind)
    path = run_dir / "checkpoints" / f"{checkpoint}.pt"
    if not path.is_file():
        raise SasmiError(f"{path}: no such checkpoint")
    return cfg, torch.load(path, map_location="cpu", weights_only=True)


def resolve_config(kind: str, out: str | os.PathLike, overrides: dict, resume: bool) -> RunConfig:
    """The config a run will use: defaults + overrides, or on resume the saved config.

    On resume only `steps` may change; any other override that differs from the saved
    value is an error, because the checkpoint was trained with the saved one.
    """
    out = Path(out)
    if not resume:
        if (out / "checkpoints" / "last.pt").exists():
            raise SasmiError(f"{out}: already holds a run; pass --resume to continue it or choose another --out")
        cfg = replace(RUN_KINDS[kind](), **overrides)
    else:
        if not (out / "checkpoints" / "last.pt").is_file():
            raise SasmiError(f"{out}: nothing to resume (no checkpoints/last.pt)")
        saved, _ = _read_config(out, kind)
        clashes = [f"{k}={v!r} (run has {getattr(saved, k)!r})" for k, v in overrides.items()
                   if k != "steps" and v != getattr(saved, k)]
        if clashes:
            raise SasmiError(f"{out}: cannot resume with changed settings: {', '.join(clashes)}")
        cfg = replace(saved, **{k: v for k, v in overrides.items() if k == "steps"})
    check_size(cfg.size)
    if cfg.steps < 1 or cfg.batch < 1:
        raise SasmiError(f"--steps and --batch must be positive (got {cfg.steps}, {cfg.batch})")
    return cfg


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        raise SasmiError(f"--device {name!r}: expected auto, cpu, cuda or cuda:N") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise SasmiError(f"--device {name}: CUDA is not available on this machine")
    return device


class Noise:
    """The run's own random stream for GP interpolates and latent codes (CPU, resumable)."""

    def __init__(self, seed: int):
        self.rng = torch.Generator().manual_seed(seed)

    def uniform(self, *shape: int) -> torch.Tensor:
        return torch.rand(shape, generator=self.rng)

    def normal(self, *shape: int) -> torch.Tensor:
        return torch.randn(shape, generator=self.rng)

    def state_dict(self) -> dict:
        return {"rng": self.rng.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.rng.set_state(state["rng"])


def grad_norm(module: torch.nn.Module) -> float:
    norms = [p.grad.norm() for p in module.parameters() if p.grad is not None]
    return float(torch.stack(norms).norm()) if norms else 0.0


def spread(n: int, k: int) -> list[int]:
    """k indices spread evenly over range(n): sample grids show every subfolder, not the first."""
    if n <= k:
        return list(range(n))
    return [round(i * (n - 1) / (k - 1)) for i in range(k)]


def image_grid(rows: list[torch.Tensor], pad: int = 2) -> torch.Tensor:
    """Rows of (n, 1, S, S) in [-1, 1] → one (1, H, W) image in [0, 1] on white."""
    n, _, s, _ = rows[0].shape
    grid = torch.ones(1, len(rows) * (s + pad) + pad, n * (s + pad) + pad)
    for r, row in enumerate(rows):
        for c, image in enumerate(to_unit(row.detach().float().cpu())):
            top, left = pad + r * (s + pad), pad + c * (s + pad)
            grid[:, top:top + s, left:left + s] = image
    return grid


@torch.no_grad()
def before_after(model: torch.nn.Module, fixed: torch.Tensor) -> list[torch.Tensor]:
    """Sample-grid rows: the fixed inputs and what the model (in eval mode) makes of them."""
    model.eval()
    rows = [fixed, model(fixed)]
    model.train()
    return rows


class Run:
    """The run folder and everything a step hands to it: logs, samples, checkpoints.

    `state` maps names to objects with state_dict/load_state_dict (models, optimisers,
    batch streams, noise); all of them go into each checkpoint.
    """

    def __init__(self, kind: str, cfg: RunConfig, out: str | os.PathLike, inputs: dict, resume: bool,
                 state: dict, samples: Callable[[], list[torch.Tensor]]):
        self.kind, self.cfg, self.out, self.state, self.samples = kind, cfg, Path(out), state, samples
        self.step, self.saved_step, self.best, self.interval = 0, 0, math.inf, []
        if resume:
            self.load()
        write_text(self.out / "config.json", json.dumps(
            {"kind": kind, "config": asdict(cfg), "inputs": {k: str(Path(v).resolve()) for k, v in inputs.items()}},
            indent=2) + "\n")
        if not resume:
            self.save("last")  # so a run that fails at once still has a good state to resume
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(str(self.out / "tb"), purge_step=self.step if resume else None)
        self.bar = tqdm(total=cfg.steps, initial=self.step, unit="step", desc=f"{kind} {self.out.name}",
                        dynamic_ncols=True, mininterval=1.0)

    def load(self) -> None:
        ckpt = torch.load(self.out / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)
        for name, obj in self.state.items():
            obj.load_state_dict(ckpt["state"][name])
        torch.set_rng_state(ckpt["torch_rng"])
        self.step = self.saved_step = ckpt["step"]
        self.best = ckpt["best"]

    def save(self, which: str) -> None:
        for name, obj in self.state.items():
            if isinstance(obj, torch.nn.Module) and not all(torch.isfinite(p).all() for p in obj.parameters()):
                raise SasmiError(f"step {self.step}: {name} weights are not finite; "
                                 f"{self.out}/checkpoints/last.pt keeps the last good state (step {self.saved_step})")
        ckpt = {"step": self.step, "best": self.best, "torch_rng": torch.get_rng_state(),
                "state": {name: obj.state_dict() for name, obj in self.state.items()}}
        with atomic_path(self.out / "checkpoints" / f"{which}.pt") as tmp:
            torch.save(ckpt, tmp)
        if which == "last":
            self.saved_step = self.step

    def write_samples(self) -> None:
        grid = image_grid(self.samples())
        write_gray(self.out / "samples" / f"step_{self.step:06d}.png", grid[0].numpy())
        self.writer.add_image("samples", grid, self.step)

    def step_done(self, step: int, scalars: dict[str, float], score: float) -> None:
        """Record a finished step; `score` (lower is better) picks best.pt."""
        bad = {k: v for k, v in scalars.items() if not math.isfinite(v)}
        if bad:
            self.close()
            raise SasmiError(f"step {step}: non-finite {', '.join(f'{k} = {v}' for k, v in bad.items())}; stopped; "
                             f"{self.out}/checkpoints/last.pt keeps the last good state (step {self.saved_step})")
        self.step = step
        self.interval.append(score)
        self.bar.update(1)
        if step % self.cfg.log_every == 0:
            for k, v in scalars.items():
                self.writer.add_scalar(k, v, step)
            self.bar.set_postfix({k.split("/")[-1]: f"{v:.3g}" for k, v in scalars.items() if k.startswith("loss/")})
        if step % self.cfg.sample_every == 0 or step == self.cfg.steps:
            self.write_samples()
        if step % self.cfg.checkpoint_every == 0 or step == self.cfg.steps:
            self.checkpoint()

    def checkpoint(self) -> None:
        score, self.interval = sum(self.interval) / len(self.interval), []
        self.writer.add_scalar("score", score, self.step)
        # a GAN's critic-based score is only meaningful once the critic has caught up
        if score < self.best and (self.kind == "autoencoder" or self.step > self.cfg.steps // 2):
            self.best = score
            self.save("best")
        self.save("last")

    def close(self) -> None:
        self.bar.close()
        self.writer.close()


# ---------------------------------------------------------------- the three loops

def train_autoencoder(cfg: AutoencoderRun, out: str | os.PathLike, real: str | os.PathLike,
                      device: torch.device, resume: bool = False) -> Path:
    """L2 reconstruction of real chips; returns the run folder."""
    # data (read before anything is written, so bad input leaves no run folder)
    real_set = ImageSet(real, cfg.size)
    batches = Batches(real_set, cfg.batch, seed=cfg.seed)
    fixed = real_set.center(spread(len(real_set), 8)).to(device)  # (n, 1, S, S) in [-1, 1]

    # model and optimiser
    torch.manual_seed(cfg.seed)  # weight initialisation; every later draw has its own stream
    model = Autoencoder(cfg.autoencoder).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=cfg.betas)

    def samples() -> list[torch.Tensor]:
        return before_after(model, fixed)

    run = Run("autoencoder", cfg, out, {"real": real}, resume,
              {"autoencoder": model, "opt": opt, "real": batches}, samples)
    for step in range(run.step + 1, cfg.steps + 1):
        # forward
        x = batches.next().to(device)  # (B, 1, S, S) in [-1, 1]
        loss = reconstruction_loss(model(x), x)
        # backward and update
        opt.zero_grad(set_to_none=True)
        loss.backward()
        norm = grad_norm(model)
        opt.step()
        # log, sample, checkpoint
        run.step_done(step, {"loss/reconstruction": loss.item(), "grad_norm/autoencoder": norm}, score=loss.item())
    run.close()
    return run.out


def critic_step(critic: Critic, opt: torch.optim.Optimizer, real: torch.Tensor, fake: torch.Tensor,
                alpha: torch.Tensor, gp_weight: float) -> dict[str, float]:
    """One critic update on (B, 1, S, S) real and detached fake batches."""
    wasserstein = -critic_loss(critic(real), critic(fake))
    penalty = gradient_penalty(critic, real, fake, alpha)
    opt.zero_grad(set_to_none=True)
    (-wasserstein + gp_weight * penalty).backward()
    norm = grad_norm(critic)
    opt.step()
    return {"loss/wasserstein": wasserstein.item(), "loss/gp": penalty.item(), "grad_norm/critic": norm}


def train_sasgan(cfg: SasganRun, out: str | os.PathLike, real: str | os.PathLike, renders: str | os.PathLike,
                 phi: str | os.PathLike, device: torch.device, resume: bool = False) -> Path:
    """Render → realistic image with WGAN-GP and the φ constraint; returns the run folder."""
    # data and the frozen φ encoder (read before anything is written)
    real_set, render_set = ImageSet(real, cfg.size), ImageSet(renders, cfg.size)
    real_batches = Batches(real_set, cfg.batch, seed=cfg.seed)
    render_batches = Batches(render_set, cfg.batch, seed=cfg.seed + 1)
    noise = Noise(cfg.seed + 2)
    fixed = render_set.center(spread(len(render_set), 8)).to(device)  # (n, 1, S, S) in [-1, 1]
    encoder = load_encoder(phi, device)
    if encoder.image_size != cfg.size:
        raise SasmiError(f"{phi}: the autoencoder was trained at {encoder.image_size} px; "
                         f"train the SAS GAN with --size {encoder.image_size} (or retrain it at {cfg.size})")

    # models and optimisers
    torch.manual_seed(cfg.seed)  # weight initialisation; every later draw has its own stream
    generator = Generator(cfg.generator).to(device)
    critic = Critic(cfg.critic, cfg.size).to(device)
    opt_g = torch.optim.Adam(generator.parameters(), lr=cfg.lr, betas=cfg.betas)
    opt_c = torch.optim.Adam(critic.parameters(), lr=cfg.lr, betas=cfg.betas)

    def samples() -> list[torch.Tensor]:
        return before_after(generator, fixed)

    run = Run("sasgan", cfg, out, {"real": real, "renders": renders, "phi": phi}, resume,
              {"generator": generator, "critic": critic, "opt_g": opt_g, "opt_c": opt_c,
               "real": real_batches, "renders": render_batches, "noise": noise}, samples)
    for step in range(run.step + 1, cfg.steps + 1):
        # critic: n_critic updates, each on fresh real and render batches
        critic.requires_grad_(True)
        for _ in range(cfg.n_critic):
            x_real = real_batches.next().to(device)  # (B, 1, S, S) in [-1, 1]
            with torch.no_grad():
                x_fake = generator(render_batches.next().to(device))
            logs = critic_step(critic, opt_c, x_real, x_fake, noise.uniform(cfg.batch, 1, 1, 1).to(device),
                               cfg.gp_weight)
        # generator: fool the critic while φ stays within γ of the render's
        critic.requires_grad_(False)
        render = render_batches.next().to(device)
        fake = generator(render)
        adversarial = generator_loss(critic(fake))
        constraint = phi_loss(encoder(render), encoder(fake), cfg.phi_margin)
        opt_g.zero_grad(set_to_none=True)
        (adversarial + cfg.phi_weight * constraint).backward()
        logs |= {"loss/generator": adversarial.item(), "loss/phi": constraint.item(),
                 "grad_norm/generator": grad_norm(generator)}
        opt_g.step()
        # log, sample, checkpoint
        run.step_done(step, logs, score=logs["loss/wasserstein"])
    run.close()
    return run.out


def train_dcgan(cfg: DcganRun, out: str | os.PathLike, real: str | os.PathLike,
                device: torch.device, resume: bool = False) -> Path:
    """The unconditional baseline with the same WGAN-GP objective; returns the run folder.

    On completion it writes cfg.final_samples images to final_samples/ for evaluation.
    """
    # data (read before anything is written)
    real_set = ImageSet(real, cfg.size)
    real_batches = Batches(real_set, cfg.batch, seed=cfg.seed)
    noise = Noise(cfg.seed + 2)
    fixed_z = torch.randn(16, cfg.dcgan.z_dim, generator=torch.Generator().manual_seed(cfg.seed + 3)).to(device)

    # models and optimisers
    torch.manual_seed(cfg.seed)  # weight initialisation; every later draw has its own stream
    generator = DCGANGenerator(cfg.dcgan, cfg.size).to(device)
    critic = Critic(cfg.critic, cfg.size).to(device)
    opt_g = torch.optim.Adam(generator.parameters(), lr=cfg.lr, betas=cfg.betas)
    opt_c = torch.optim.Adam(critic.parameters(), lr=cfg.lr, betas=cfg.betas)

    @torch.no_grad()
    def samples() -> list[torch.Tensor]:
        generator.eval()
        rows = list(generator(fixed_z).split(8))
        generator.train()
        return rows

    run = Run("dcgan", cfg, out, {"real": real}, resume,
              {"generator": generator, "critic": critic, "opt_g": opt_g, "opt_c": opt_c,
               "real": real_batches, "noise": noise}, samples)
    for step in range(run.step + 1, cfg.steps + 1):
        # critic: n_critic updates, each on a fresh real batch and fresh codes
        critic.requires_grad_(True)
        for _ in range(cfg.n_critic):
            x_real = real_batches.next().to(device)  # (B, 1, S, S) in [-1, 1]
            with torch.no_grad():
                x_fake = generator(noise.normal(cfg.batch, cfg.dcgan.z_dim).to(device))
            logs = critic_step(critic, opt_c, x_real, x_fake, noise.uniform(cfg.batch, 1, 1, 1).to(device),
                               cfg.gp_weight)
        # generator: fool the critic
        critic.requires_grad_(False)
        adversarial = generator_loss(critic(generator(noise.normal(cfg.batch, cfg.dcgan.z_dim).to(device))))
        opt_g.zero_grad(set_to_none=True)
        adversarial.backward()
        logs |= {"loss/generator": adversarial.item(), "grad_norm/generator": grad_norm(generator)}
        opt_g.step()
        # log, sample, checkpoint
        run.step_done(step, logs, score=logs["loss/wasserstein"])
    run.close()

    # final samples for the evaluation
    for i, image in enumerate(sample(generator, cfg.final_samples, seed=cfg.seed)):
        write_gray(run.out / "final_samples" / f"{i:06d}.png", image)
    return run.out


# ---------------------------------------------------------------- loading trained nets

def load_generator(run_dir: str | os.PathLike, device: str | torch.device = "cpu",
                   checkpoint: str = "last") -> Generator:
    """The SAS GAN generator of a run: (B, 1, S, S) in [-1, 1] → same; `.image_size` = S; eval mode."""
    cfg, state = read_run(run_dir, "sasgan", checkpoint)
    generator = Generator(cfg.generator)
    generator.load_state_dict(state["state"]["generator"])
    generator = generator.to(device).eval().requires_grad_(False)
    generator.image_size = cfg.size
    return generator


def load_dcgan(run_dir: str | os.PathLike, device: str | torch.device = "cpu",
               checkpoint: str = "last") -> DCGANGenerator:
    """The DCGAN generator of a run: (B, z_dim) → (B, 1, S, S) in [-1, 1]; `.image_size` = S; eval mode.

    gan.dcgan.sample(generator, n, seed) turns it into n images in [0, 1].
    """
    cfg, state = read_run(run_dir, "dcgan", checkpoint)
    generator = DCGANGenerator(cfg.dcgan, cfg.size)
    generator.load_state_dict(state["state"]["generator"])
    generator = generator.to(device).eval().requires_grad_(False)
    generator.image_size = cfg.size
    return generator
