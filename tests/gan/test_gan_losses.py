"""The WGAN-GP and φ losses as pure functions."""
import pytest
import torch
import torch.nn.functional as F

from sasmi.gan.critic import Critic, CriticConfig
from sasmi.gan.losses import (critic_loss, generator_loss, gradient_penalty, phi_distribution_loss, phi_loss,
                              reconstruction_loss)


def test_wasserstein_terms():
    real, fake = torch.tensor([2.0, 4.0]), torch.tensor([1.0, -1.0])
    assert critic_loss(real, fake) == -3.0  # −(mean real − mean fake)
    assert generator_loss(fake) == 0.0


def test_gradient_penalty_gradcheck_float64():
    torch.manual_seed(0)
    real = torch.randn(2, 1, 4, 4, dtype=torch.float64, requires_grad=True)
    fake = torch.randn(2, 1, 4, 4, dtype=torch.float64, requires_grad=True)
    weight = torch.randn(3, 1, 3, 3, dtype=torch.float64, requires_grad=True)
    alpha = torch.rand(2, 1, 1, 1, dtype=torch.float64)

    # a smooth critic, so the penalty's second derivatives are not piecewise constant
    def penalty(w, r, f):
        return gradient_penalty(lambda x: torch.tanh(F.conv2d(x, w)).pow(2).sum(dim=(1, 2, 3)), r, f, alpha)

    assert torch.autograd.gradcheck(penalty, (weight, real, fake))


def test_gradient_penalty_of_the_real_critic_trains_its_weights():
    torch.manual_seed(0)
    critic = Critic(CriticConfig(width=4), 32).double()
    real, fake = torch.rand(2, 2, 1, 32, 32, dtype=torch.float64) * 2 - 1
    gp = gradient_penalty(critic, real, fake, torch.rand(2, 1, 1, 1, dtype=torch.float64))
    gp.backward()
    assert gp > 0
    # every weight shapes ∇ₓD; the biases of the last layer cannot
    weights = [p for name, p in critic.named_parameters() if "weight" in name]
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in weights)


def test_gradient_penalty_is_zero_for_a_unit_norm_linear_critic():
    torch.manual_seed(0)
    w = torch.randn(1, 1, 16, 16)
    w = w / w.norm()

    def critic(x):
        return (x * w).sum(dim=(1, 2, 3))

    real, fake = torch.randn(2, 4, 1, 16, 16)
    assert gradient_penalty(critic, real, fake, torch.rand(4, 1, 1, 1)) < 1e-10
    steep = gradient_penalty(lambda x: 3 * critic(x), real, fake, torch.rand(4, 1, 1, 1))
    assert torch.isclose(steep, torch.tensor(4.0))  # (‖3w‖ − 1)² = 4


def test_phi_loss_is_a_hinge_on_relative_distance():
    a = torch.tensor([[3.0, 4.0], [1.0, 0.0]])  # norms 5 and 1
    inside = a + torch.tensor([[0.5, 0.0], [0.05, 0.0]])  # relative distances 0.1 and 0.05
    assert phi_loss(a, inside, margin=0.25) == 0
    outside = a + torch.tensor([[2.5, 0.0], [0.0, 0.0]])  # 0.5 and 0
    assert torch.isclose(phi_loss(a, outside, margin=0.25), torch.tensor(0.125))  # mean(0.25, 0)
    b = outside.clone().requires_grad_(True)
    phi_loss(a, b, 0.25).backward()
    assert b.grad[0].abs().sum() > 0 and b.grad[1].abs().sum() == 0


def test_reconstruction_loss_is_mse():
    assert reconstruction_loss(torch.zeros(2, 1, 4, 4), torch.ones(2, 1, 4, 4)) == 1.0


def test_phi_distribution_loss_sees_the_spread_that_the_mean_hides():
    """Two sets of the same mean φ, one as spread as the real chips and one four times narrower: the mean's
    term cannot tell them apart, the spreads' term can; each term relative to the real vector's size."""
    torch.manual_seed(0)
    real_mean, real_spread = torch.randn(8), torch.rand(8) + 0.5
    unit = torch.randn(200, 8)
    unit = (unit - unit.mean(0)) / unit.std(0)  # sample mean 0 and standard deviation 1 per feature
    wide, narrow = real_mean + unit * real_spread, real_mean + unit * real_spread / 4
    for weight in (0.0, 1.0):
        assert phi_distribution_loss(wide, real_mean, real_spread, weight) < 1e-5
    assert phi_distribution_loss(narrow, real_mean, real_spread, 0.0) < 1e-5
    assert phi_distribution_loss(narrow, real_mean, real_spread, 1.0).item() == pytest.approx(0.75, abs=1e-5)
    shifted = wide + real_mean.norm() * 0.1 / 8 ** 0.5  # every feature moved: the means 10 % apart
    assert phi_distribution_loss(shifted, real_mean, real_spread, 2.0).item() == pytest.approx(0.1, abs=1e-5)
    assert phi_distribution_loss(narrow + (shifted - wide), real_mean, real_spread, 2.0).item() == pytest.approx(
        0.1 + 2 * 0.75, abs=1e-5)


def test_a_fit_of_four_chips_by_phi_distribution_loss_keeps_their_spread():
    """A fit renders a few scenes, whose spread is noisy. Sets of 4 chips drawn from the real chips'
    distribution, each scaled by the factor that minimises the loss: on average that factor is 1. (The norm of
    per-feature spread differences would shrink them, to about 0.85: each feature's spread is 40 % noise.)"""
    torch.manual_seed(1)
    real_spread, real_mean = torch.rand(256) + 0.5, torch.randn(256)
    factors = torch.linspace(0.5, 1.5, 201)
    best = []
    for _ in range(40):
        spread = torch.randn(4, 256) * real_spread
        spread -= spread.mean(0)  # the means' term aside
        losses = torch.stack([phi_distribution_loss(real_mean + spread * f, real_mean, real_spread, 1.0)
                              for f in factors])
        best.append(factors[losses.argmin()].item())
    assert sum(best) / len(best) == pytest.approx(1.0, abs=0.03)
