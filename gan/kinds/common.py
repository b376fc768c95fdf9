"""Pieces the run kinds share: the GANs' config and critic phase, noise, sample helpers."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterable

import torch

from sasmi.gan.augment import AugmentConfig, augment
from sasmi.gan.critic import Critic, CriticConfig
from sasmi.gan.distributed import draw
from sasmi.gan.loop import Logs
from sasmi.gan.losses import (critic_loss, generator_loss, gradient_penalty, logistic_critic_loss, logistic_generator_loss,
                        r1_penalty)
from sasmi.gan.run import RunConfig, check_number
from sasmi.errors import SasmiError

REGULARISERS = ("gp", "r1")


@dataclass(frozen=True)
class GanRun(RunConfig):
    steps: int = 1000  # generator updates; at 128² the GANs are still improving at 700-900
    betas: tuple[float, float] = (0.5, 0.9)  # WGAN-GP's β2 = 0.9 with DCGAN's β1 = 0.5
    best_from: int = 500  # the Wasserstein estimate is near zero while the critic is still untrained
    n_critic: int = 5  # critic updates per generator update (WGAN-GP)
    critic_lr: float | None = None  # the critic's Adam rate; None: the same as lr
    regulariser: str = "gp"  # "gp": Wasserstein loss + gradient penalty; "r1": logistic loss + R1 (StyleGAN2)
    gp_weight: float = 10.0  # λ of the gradient penalty (WGAN-GP, Reed et al.)
    r1_gamma: float = 1.0  # γ of R1 (penalty γ/2·‖∇D(real)‖²); StyleGAN2-ADA's rule gives 0.8 at 128², batch 4
    augment: AugmentConfig = AugmentConfig()  # what the critic sees of real and fake alike; off by default
    critic: CriticConfig = CriticConfig()

    def validate(self) -> "GanRun":
        super().validate()
        check_number("--n-critic", self.n_critic)
        if self.critic_lr is not None:
            check_number("--critic-lr", self.critic_lr)
        if self.regulariser not in REGULARISERS:
            raise SasmiError(f"--regulariser {self.regulariser}: expected one of {', '.join(REGULARISERS)}")
        check_number("--gp-weight", self.gp_weight)
        check_number("--r1-gamma", self.r1_gamma)
        if self.critic.phi_features and self.critic.patch:
            raise SasmiError("critic.phi_features and critic.patch: choose one (the φ critic's heads see whole maps)")
        if self.critic.phi_features and self.critic.standardise:
            raise SasmiError("critic.phi_features and critic.standardise: choose one (φ reads chips in [-1, 1])")
        a = self.augment
        check_number("augment.translation", a.translation)
        check_number("augment.cutout", a.cutout)
        check_number("augment.brightness", a.brightness)
        check_number("augment.contrast", a.contrast)
        return self


class Noise:
    """One of the run's own random streams (GP interpolates, latent codes, augmentation); CPU, resumable."""

    def __init__(self, seed: int):
        self.rng = torch.Generator().manual_seed(seed)

    def uniform(self, n: int, *shape: int) -> torch.Tensor:
        """(n, *shape) in [0, 1): this process's n of the global batch's draws (gan/distributed.py)."""
        return draw(self.rng, n, *shape)

    def normal(self, n: int, *shape: int) -> torch.Tensor:
        return draw(self.rng, n, *shape, normal=True)

    def state_dict(self) -> dict:
        return {"rng": self.rng.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.rng.set_state(state["rng"])


def adam(params: Iterable[torch.nn.Parameter], lr: float, cfg: RunConfig) -> torch.optim.Adam:
    return torch.optim.Adam(params, lr=lr, betas=cfg.betas)


def grad_norm(module: torch.nn.Module) -> float:
    norms = [p.grad.norm() for p in module.parameters() if p.grad is not None]
    return float(torch.stack(norms).norm()) if norms else 0.0


def spread(n: int, k: int) -> list[int]:
    """k indices spread evenly over range(n): sample grids show every subfolder, not the first."""
    if n <= k:
        return list(range(n))
    return [round(i * (n - 1) / (k - 1)) for i in range(k)]


@torch.no_grad()
def before_after(model: torch.nn.Module, fixed: torch.Tensor, code: torch.Tensor | None = None) -> list[torch.Tensor]:
    """Sample-grid rows: the fixed inputs and what the model (in eval mode) makes of them, with
    `code` (len(fixed), model.style_size) where the model reads one."""
    model.eval()
    rows = [fixed, model(fixed, code=code.to(fixed.device)) if getattr(model, "style_size", 0) else model(fixed)]
    model.train()
    return rows


def critic_view(cfg: GanRun, noise: Noise) -> Callable[[torch.Tensor], torch.Tensor]:
    """What the critic sees of an image batch: cfg.augment's differentiable transforms."""
    return lambda x: augment(x, cfg.augment, noise.rng)


def adversarial_loss(cfg: GanRun, fake_scores: torch.Tensor) -> torch.Tensor:
    """The generator's side of cfg.regulariser's objective; (B,) → scalar."""
    return generator_loss(fake_scores) if cfg.regulariser == "gp" else logistic_generator_loss(fake_scores)


def critic_phase(cfg: GanRun, critic: Critic, opt: torch.optim.Optimizer, real: Callable[[], torch.Tensor],
                 fake: Callable[[], torch.Tensor], view: Callable[[torch.Tensor], torch.Tensor], noise: Noise,
                 device: torch.device) -> Callable[[], Logs]:
    """One critic update on a fresh real batch and a fresh (detached) fake batch, both seen through `view`."""

    def step() -> Logs:
        critic.requires_grad_(True)
        x_real = view(real())  # (B, 1, S, S) in [-1, 1] (roughly: brightness may push past)
        with torch.no_grad():
            x_fake = view(fake())  # (B, 1, S, S), no gradient to the generator
        s_real, s_fake = critic(torch.cat([x_real, x_fake])).split(len(x_real))  # (B,) each; one pass is faster
        if cfg.regulariser == "gp":
            loss = critic_loss(s_real, s_fake)  # −W
            alpha = noise.uniform(len(x_real), 1, 1, 1).to(device)
            penalty = gradient_penalty(critic, x_real, x_fake, alpha)
            total = loss + cfg.gp_weight * penalty
        else:
            loss = logistic_critic_loss(s_real, s_fake)
            penalty = r1_penalty(critic, x_real)
            total = loss + 0.5 * cfg.r1_gamma * penalty
        opt.zero_grad(set_to_none=True)
        total.backward()
        norm = grad_norm(critic)
        opt.step()
        critic.requires_grad_(False)
        return {"loss/wasserstein": (s_real.mean() - s_fake.mean()).item(), "loss/critic": loss.item(),
                f"loss/{cfg.regulariser}": penalty.item(), "grad_norm/critic": norm}

    return step
