"""Losses as pure functions of scores, images and features; the training loop weights them.

WGAN-GP (Gulrajani et al. 2017): the critic maximises mean D(real) − mean D(fake) while
a penalty keeps its gradient norm near 1 at random interpolates, λ = 10. The SAS GAN adds
the φ constraint of Reed et al.: the generator may change an image's φ only by a margin.
"""
from __future__ import annotations

from typing import Callable

import torch


def critic_loss(real_scores: torch.Tensor, fake_scores: torch.Tensor) -> torch.Tensor:
    """Negative Wasserstein estimate; (B,) scores → scalar. Minimised by the critic."""
    return fake_scores.mean() - real_scores.mean()


def generator_loss(fake_scores: torch.Tensor) -> torch.Tensor:
    """(B,) scores of generated images → scalar. Minimised by the generator."""
    return -fake_scores.mean()


def gradient_penalty(critic: Callable[[torch.Tensor], torch.Tensor], real: torch.Tensor,
                     fake: torch.Tensor, alpha: torch.Tensor) -> torch.Tensor:
    """mean over the batch of (‖∇ₓ D(x̂)‖₂ − 1)², x̂ = α·real + (1 − α)·fake.

    real, fake: (B, 1, S, S); alpha: (B, 1, 1, 1) in [0, 1], drawn by the caller so that
    its random stream belongs to the run's resumable state. Differentiable with respect
    to the critic's weights (create_graph), which is what trains the critic.
    """
    assert real.shape == fake.shape and alpha.shape == (real.shape[0], 1, 1, 1), (real.shape, fake.shape, alpha.shape)
    x = (alpha * real + (1.0 - alpha) * fake).requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x).sum(), x, create_graph=True)
    return ((grad.flatten(1).norm(dim=1) - 1.0) ** 2).mean()


def phi_loss(phi_a: torch.Tensor, phi_b: torch.Tensor, margin: float) -> torch.Tensor:
    """Hinge on the relative φ distance: mean over the batch of max(0, ‖φa − φb‖ / ‖φa‖ − γ).

    phi_a: (B, D) of the renders, phi_b: (B, D) of the generated images. Zero while the
    generator stays within γ of the render's φ (Reed et al.'s constraint), linear beyond.
    Dividing by ‖φa‖ makes γ a fraction (0.25 = a quarter of the render's φ norm) that
    does not depend on the scale a particular autoencoder run happened to learn.
    """
    assert phi_a.shape == phi_b.shape and phi_a.ndim == 2, (phi_a.shape, phi_b.shape)
    distance = (phi_b - phi_a).norm(dim=1) / phi_a.norm(dim=1).clamp_min(1e-8)
    return (distance - margin).clamp_min(0.0).mean()


def reconstruction_loss(reconstruction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error (the autoencoder's L2), images in [-1, 1]."""
    return ((reconstruction - target) ** 2).mean()
