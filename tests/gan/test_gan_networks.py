"""Shapes and value ranges of the GAN networks at test sizes (32 and 64 px)."""
import pytest
import torch

from sasmi.gan.autoencoder import PHI_DIM, Autoencoder, AutoencoderConfig
from sasmi.gan.critic import Critic, CriticConfig
from sasmi.gan.dcgan import DCGANConfig, DCGANGenerator, sample
from sasmi.gan.generator import GENERATOR_NETS, Generator, GeneratorConfig


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.mark.parametrize("size", [32, 64])
def test_autoencoder_phi_is_1024_at_any_size(size):
    ae = Autoencoder(AutoencoderConfig())
    x = torch.rand(3, 1, size, size) * 2 - 1
    phi = ae.encoder(x)
    assert phi.shape == (3, PHI_DIM)
    assert (phi >= 0).all()  # ReLU features
    y = ae(x)
    assert y.shape == x.shape and y.abs().max() <= 1


def test_autoencoder_phi_is_the_flattened_last_stage_at_128():
    ae = Autoencoder(AutoencoderConfig())
    x = torch.rand(1, 1, 128, 128) * 2 - 1
    assert torch.equal(ae.encoder(x), ae.encoder.stages(x).flatten(1))


def test_autoencoder_widths_must_give_1024():
    with pytest.raises(ValueError):
        AutoencoderConfig(widths=(8, 8, 8, 8))


@pytest.mark.parametrize("size", [32, 64])
@pytest.mark.parametrize("residual", [False, True])
def test_generator_keeps_shape_and_range(size, residual):
    g = Generator(GeneratorConfig(width=8, blocks=2, residual=residual))
    x = torch.rand(2, 1, size, size) * 2 - 1
    y = g(x)
    assert y.shape == x.shape
    assert y.min() >= -1 and y.max() <= 1


def test_residual_generator_starts_as_the_render_and_can_leave_it():
    g = Generator(GeneratorConfig(width=8, blocks=1, residual=True))
    x = torch.rand(2, 1, 32, 32) * 1.8 - 0.9  # inside RENDER_REACH: no clamping
    assert torch.allclose(g(x), x, atol=1e-5)
    assert not torch.allclose(Generator(GeneratorConfig(width=8, blocks=1))(x), x, atol=0.1)
    # the zero-initialised last conv still learns: one step moves the output toward a target
    opt = torch.optim.Adam(g.parameters(), lr=1e-2)
    ((g(x) - 0.5) ** 2).mean().backward()
    opt.step()
    assert ((g(x) - 0.5) ** 2).mean() < ((x - 0.5) ** 2).mean()
    y = g(torch.ones(1, 1, 32, 32).tril() * 2 - 1)  # black and white render pixels, beyond RENDER_REACH
    assert y.min() >= -1 and y.max() <= 1


def test_correction_scale_keeps_the_renders_speckle():
    """GeneratorConfig.correction_scale: the residual correction is smooth over that many px, so
    the render's pixel-scale speckle passes through (the output / render pattern has no pixel-to-pixel
    noise); at scale 1 the same weights change single pixels."""
    from sasmi.gan.generator import RENDER_REACH

    torch.manual_seed(0)
    x = torch.rand(2, 1, 64, 64) * 1.8 - 0.9  # speckle-like: independent pixels

    def correction(scale: int) -> torch.Tensor:
        g = Generator(GeneratorConfig(width=8, blocks=1, residual=True, correction_scale=scale))
        torch.manual_seed(1)
        torch.nn.init.normal_(g.net[-1].weight, std=0.2)  # as after training: not zero
        with torch.no_grad():
            return torch.atanh(g(x).clamp(-0.9999, 0.9999)) - torch.atanh(x.clamp(-RENDER_REACH, RENDER_REACH))

    def roughness(c: torch.Tensor) -> float:  # mean 1-px step relative to the correction's spread
        return float((c[..., 1:] - c[..., :-1]).abs().mean() / c.std())

    smooth, per_pixel = correction(4), correction(1)
    assert smooth.abs().mean() > 0.05  # it does correct
    assert roughness(smooth) < 0.5 * roughness(per_pixel), (roughness(smooth), roughness(per_pixel))


def test_generator_presets_differ_only_in_size():
    small, paper = (sum(p.numel() for p in Generator(GENERATOR_NETS[k]).parameters()) for k in ("small", "paper"))
    assert small < paper / 10


@pytest.mark.parametrize("size", [32, 64])
def test_critic_scores_one_number_per_image_without_batch_norm(size):
    critic = Critic(CriticConfig(width=8), size)
    assert not any(isinstance(m, torch.nn.modules.batchnorm._BatchNorm) for m in critic.modules())
    scores = critic(torch.rand(5, 1, size, size) * 2 - 1)
    assert scores.shape == (5,)
    # per-sample: a sample's score does not depend on the rest of the batch
    x = torch.rand(4, 1, size, size)
    assert torch.allclose(critic(x)[:1], critic(x[:1]), atol=1e-6)


def test_patch_critic_scores_a_pattern_alike_wherever_it_lies():
    """CriticConfig.patch: one shared score per patch, averaged, so a bright mark moved by the
    critic's stride (16 px) inside a flat chip scores the same; the whole-chip linear unit
    weighs each position on its own, so there it does not."""
    torch.manual_seed(0)

    def chip_with_mark(at: int) -> torch.Tensor:
        x = torch.full((1, 1, 128, 128), -0.5)
        x[..., at:at + 5, at:at + 5] = 0.8
        return x

    moved = torch.cat([chip_with_mark(54), chip_with_mark(70)])
    patch, whole = Critic(CriticConfig(width=8, patch=True), 128), Critic(CriticConfig(width=8), 128)
    assert torch.allclose(*patch(moved), atol=1e-6)
    assert not torch.allclose(*whole(moved), atol=1e-4)
    assert sum(p.numel() for p in patch.score.parameters()) == 8 * 8 + 1  # the same at any size


@pytest.mark.parametrize("size", [32, 64])
def test_dcgan_generator_and_sample(size):
    g = DCGANGenerator(DCGANConfig(z_dim=16, width=8), size)
    y = g(torch.randn(3, 16))
    assert y.shape == (3, 1, size, size) and y.abs().max() <= 1
    a, b = sample(g, 5, seed=1, batch=2), sample(g, 5, seed=1)
    assert a.shape == (5, size, size) and a.dtype.name == "float32"
    assert a.min() >= 0 and a.max() <= 1
    assert abs(a - b).max() < 1e-5  # same seed, same images, whatever the batch
