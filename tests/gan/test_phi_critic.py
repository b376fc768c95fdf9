"""The critic on φ's feature maps (CriticConfig.phi_features): it learns, φ stays frozen, runs resume."""

import pytest
import torch

from sasmi.errors import SasmiError
from sasmi.gan.autoencoder import AutoencoderConfig, Encoder
from sasmi.gan.critic import CriticConfig, PhiCritic, make_critic
from sasmi.gan.generator import GeneratorConfig
from sasmi.gan.kinds.common import GanRun, Noise, critic_phase, critic_view
from sasmi.gan.kinds.dcgan import DcganRun
from sasmi.gan.kinds.sasgan import SasganRun
from test_gan_train import sasgan_straight_and_resumed, toy_gan_inputs

CPU = torch.device("cpu")
SIZE = 32
PHI_CRITIC = CriticConfig(4, phi_features=True)


def _encoder() -> Encoder:
    torch.manual_seed(0)
    return Encoder(AutoencoderConfig()).eval().requires_grad_(False)


def test_feature_maps_are_the_stages_that_end_in_phi():
    encoder = _encoder()
    x = torch.rand(2, 1, 128, 128) * 2 - 1
    maps = encoder.feature_maps(x)
    assert [m.shape[1:] for m in maps] == [(32, 64, 64), (64, 32, 32), (128, 16, 16), (16, 8, 8)]
    torch.testing.assert_close(maps[-1].flatten(1), encoder(x))  # at 128 px φ is the last map, flattened


def test_phi_critic_separates_real_from_fake_and_leaves_phi_as_it_is():
    encoder = _encoder()
    before = [p.clone() for p in encoder.parameters()]
    critic = make_critic(PHI_CRITIC, SIZE, encoder)
    assert isinstance(critic, PhiCritic)
    assert not any(k.startswith("encoder") for k in critic.state_dict())  # φ is not the critic's to save
    rng = torch.Generator().manual_seed(1)

    def stream(mean):
        return lambda: (mean + 0.2 * torch.randn(8, 1, SIZE, SIZE, generator=rng)).clamp(-1, 1)

    cfg = GanRun(size=SIZE)
    step = critic_phase(cfg, critic, torch.optim.Adam(critic.parameters(), lr=1e-3, betas=(0.5, 0.9)),
                        stream(0.3), stream(-0.3), critic_view(cfg, Noise(2)), Noise(0), CPU)
    logs = [step() for _ in range(30)]
    assert logs[-1]["loss/wasserstein"] > 0.5, logs[-1]  # real scored above fake
    for b, p in zip(before, encoder.parameters()):
        assert torch.equal(b, p) and not p.requires_grad  # the critic's updates never reached φ


def test_a_sasgan_with_the_phi_critic_trains_and_resumes_exactly(tmp_path):
    data = toy_gan_inputs(tmp_path / "data", SIZE, phi_steps=5)
    cfg = SasganRun(size=SIZE, batch=2, n_critic=1, steps=4, generator=GeneratorConfig(4, 1), critic=PHI_CRITIC,
                    sample_every=100, checkpoint_every=2, ema=0.0)
    a, b = (state["critic"] for state in sasgan_straight_and_resumed(cfg, tmp_path, data))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("run", [SasganRun(critic=CriticConfig(phi_features=True, patch=True)),
                                 DcganRun(critic=CriticConfig(phi_features=True))])
def test_phi_critic_settings_that_cannot_work_are_refused(run):
    with pytest.raises(SasmiError, match="phi_features"):
        run.validate()
