"""Pieces the run kinds share: the GANs' config and critic phase, noise, sample helpers."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

from gan.critic import Critic, CriticConfig
from gan.loop import Logs
from gan.losses import critic_loss, gradient_penalty
from gan.run import RunConfig, check_number


@dataclass(frozen=True)
class GanRun(RunConfig):
    steps: int = 1000  # generator updates; README's 128² runs: 700 (SAS GAN) and 900 (DCGAN) were short
    betas: tuple[float, float] = (0.5, 0.9)  # WGAN-GP's β2 = 0.9 with DCGAN's β1 = 0.5
    best_from: int = 500  # the Wasserstein estimate is near zero while the critic is still untrained
    n_critic: int = 5  # critic updates per generator update (WGAN-GP)
    gp_weight: float = 10.0  # λ of the gradient penalty (WGAN-GP, Reed et al.)
    critic: CriticConfig = CriticConfig()

    def validate(self) -> "GanRun":
        super().validate()
        check_number("--n-critic", self.n_critic, 1, 100, integer=True, why="critic updates per generator update")
        check_number("--gp-weight", self.gp_weight, 0.0, 1e4)
        return self


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


@torch.no_grad()
def before_after(model: torch.nn.Module, fixed: torch.Tensor) -> list[torch.Tensor]:
    """Sample-grid rows: the fixed inputs and what the model (in eval mode) makes of them."""
    model.eval()
    rows = [fixed, model(fixed)]
    model.train()
    return rows


def critic_phase(cfg: GanRun, critic: Critic, opt: torch.optim.Optimizer, real: Callable[[], torch.Tensor],
                 fake: Callable[[], torch.Tensor], noise: Noise, device: torch.device) -> Callable[[], Logs]:
    """One WGAN-GP critic update on a fresh real batch and a fresh (detached) fake batch."""

    def step() -> Logs:
        critic.requires_grad_(True)
        x_real = real()  # (B, 1, S, S) in [-1, 1]
        with torch.no_grad():
            x_fake = fake()  # (B, 1, S, S) in [-1, 1], no gradient to the generator
        loss = critic_loss(critic(x_real), critic(x_fake))  # −W
        penalty = gradient_penalty(critic, x_real, x_fake, noise.uniform(len(x_real), 1, 1, 1).to(device))
        opt.zero_grad(set_to_none=True)
        (loss + cfg.gp_weight * penalty).backward()
        norm = grad_norm(critic)
        opt.step()
        critic.requires_grad_(False)
        return {"loss/wasserstein": -loss.item(), "loss/gp": penalty.item(), "grad_norm/critic": norm}

    return step
