"""The training phases do what their names say: tests that fail when the loop is wrong.

Each fails under one deliberate mutation of the loop: real and fake swapped in the critic loss,
the gradient penalty dropped, the φ term dropped, a generator step that does not update the generator.
"""
from dataclasses import replace

import numpy as np
import pytest
import torch

from sasmi.gan.autoencoder import load_encoder
from sasmi.gan.critic import Critic, CriticConfig
from sasmi.gan.data import ImageSet
from sasmi.gan.generator import GeneratorConfig
from sasmi.gan.kinds.common import GanRun, Noise, critic_phase, critic_view
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.losses import phi_loss
from test_gan_train import toy_gan_inputs

CPU = torch.device("cpu")
SIZE = 32


def _stream(mean: float, rng: torch.Generator, batch: int = 8):
    return lambda: (mean + 0.2 * torch.randn(batch, 1, SIZE, SIZE, generator=rng)).clamp(-1, 1)


def _trained_critic(gp_weight: float = 10.0, steps: int = 40, **overrides):
    """A critic trained on bright 'real' against dark 'fake' toy images; returns it and the streams."""
    torch.manual_seed(0)
    rng = torch.Generator().manual_seed(1)
    real, fake = _stream(0.3, rng), _stream(-0.3, rng)
    critic = Critic(CriticConfig(4), SIZE)
    opt = torch.optim.Adam(critic.parameters(), lr=1e-3, betas=(0.5, 0.9))
    cfg = replace(GanRun(size=SIZE, gp_weight=gp_weight), **overrides)
    step = critic_phase(cfg, critic, opt, real, fake, critic_view(cfg, Noise(2)), Noise(0), CPU)
    for _ in range(steps):
        logs = step()
    return critic, real, fake, logs


def _interpolate_grad_norm(critic, real, fake) -> float:
    x = (0.5 * real() + 0.5 * fake()).requires_grad_(True)
    critic.requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x).sum(), x)
    return grad.flatten(1).norm(dim=1).mean().item()


def test_critic_separates_real_from_fake_in_a_few_steps():
    critic, real, fake, logs = _trained_critic(gp_weight=10.0)
    with torch.no_grad():
        margin = critic(real()).mean() - critic(fake()).mean()
    assert margin > 1.0, margin  # real scores above fake ones: not the other way round
    assert logs["loss/wasserstein"] > 1.0, logs


def test_gradient_penalty_keeps_the_critic_near_1_lipschitz():
    with_gp = _interpolate_grad_norm(*_trained_critic(gp_weight=10.0)[:3])
    without = _interpolate_grad_norm(*_trained_critic(gp_weight=0.0)[:3])
    assert with_gp < 3.0, with_gp  # near 1: the penalty's target
    assert without > 2 * with_gp, (with_gp, without)  # the penalty is what holds it


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """'Real' speckle chips, renders (disc + shadow), and a φ autoencoder trained 30 steps on the real ones."""
    return toy_gan_inputs(tmp_path_factory.mktemp("loop"), SIZE, phi_steps=30)


def _phases(data, **overrides):
    cfg = replace(SasganRun(size=SIZE, batch=4, n_critic=1, generator=GeneratorConfig(4, 1),
                            critic=CriticConfig(4)), **overrides)
    torch.manual_seed(cfg.seed)  # as the loop does before building
    return SASGAN.build(cfg, data, CPU)


def _params(module) -> list[torch.Tensor]:
    return [p.detach().clone() for p in module.parameters()]


def _changed(before, module) -> float:
    """The fraction of parameter tensors that moved."""
    return float(np.mean([not torch.equal(a, b) for a, b in zip(before, module.parameters())]))


def test_each_step_updates_its_own_network_only(data):
    phases = _phases(data)
    generator, critic = phases.state["generator"], phases.state["critic"]
    g0, c0 = _params(generator), _params(critic)
    phases.critic_step()
    # every critic tensor moves but the score's bias, which cancels in mean D(real) − mean D(fake)
    assert _changed(c0, critic) == 0.9 and _changed(g0, generator) == 0.0
    c1 = _params(critic)
    phases.generator_step()
    assert _changed(g0, generator) == 1.0 and _changed(c1, critic) == 0.0


def test_generator_steps_raise_the_critic_score_of_fakes(data):
    phases = _phases(data, phi_weight=0.0)
    generator, critic = phases.state["generator"], phases.state["critic"]
    for _ in range(20):
        phases.critic_step()
    renders = ImageSet(data["renders"], SIZE).center(list(range(8)))
    with torch.no_grad():
        before = critic(generator(renders)).mean().item()
    for _ in range(10):
        phases.generator_step()
    with torch.no_grad():
        after = critic(generator(renders)).mean().item()
    assert after > before, (before, after)


def test_phi_weight_keeps_the_generator_near_the_render(data):
    encoder = load_encoder(data["phi"])
    renders = ImageSet(data["renders"], SIZE).center(list(range(8)))  # (8, 1, S, S) in [-1, 1]
    distance = {}
    for weight in (0.0, 1000.0):
        phases = _phases(data, phi_weight=weight, phi_margin=0.0)
        for _ in range(15):
            phases.generator_step()
        with torch.no_grad():
            distance[weight] = phi_loss(encoder(renders), encoder(phases.state["generator"](renders)), 0.0).item()
    assert distance[1000.0] < 0.5 * distance[0.0], distance  # the φ term holds the output near its render
