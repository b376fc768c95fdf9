"""The tone style: a random code per chip beside the render's gray levels chooses its tone curve,
so that one render can take any of many gray-level distributions instead of one fixed by the
render; training draws the codes from the run's resumable stream, translation from a seeded one."""
import numpy as np
import pytest
import torch

from sasmi.errors import SasmiError
from sasmi.gan.critic import CriticConfig
from sasmi.gan.generator import TONE_STYLE, Generator, GeneratorConfig, ToneCurve
from sasmi.gan.kinds.sasgan import SasganRun
from sasmi.gan.losses import energy_distance, gray_levels
from sasmi.gan.translate import translate, translate_folder
from sasmi.images import read_gray
from test_gan_train import make_render_set, sasgan_straight_and_resumed, toy_gan_inputs

STYLED = GeneratorConfig(4, 1, residual=True, correction_scale=4, tone_curve=True, tone_style=True)


def _ramp(n: int, size: int = 16) -> torch.Tensor:
    """(n, 1, S, S) copies of one render whose gray levels cover [-1, 1] evenly."""
    return torch.linspace(-1, 1, size * size).view(1, 1, size, size).expand(n, 1, size, size).contiguous()


def _randomise(curve: ToneCurve) -> None:
    torch.manual_seed(1)
    for p in curve.parameters():
        torch.nn.init.normal_(p, std=0.3)  # curves that differ smoothly, none saturated


def test_the_code_chooses_the_curve_and_the_identity_holds_at_first():
    curve = ToneCurve(style=TONE_STYLE)
    x = _ramp(3)
    torch.testing.assert_close(curve(x), x)  # whatever code is drawn: training starts at the render
    _randomise(curve)
    a, b = torch.randn(3, TONE_STYLE), torch.randn(3, TONE_STYLE)
    torch.testing.assert_close(curve(x, a), curve(x, a))
    assert (curve(x, a) - curve(x, b)).abs().amax(dim=(1, 2, 3)).min() > 1e-3  # one render, many curves
    assert (curve(x, a).diff(dim=-1) >= 0).all()  # still monotone
    assert Generator(STYLED).style_size == TONE_STYLE
    assert Generator(GeneratorConfig(4, 1, residual=True, tone_curve=True)).style_size == 0


def test_tone_style_without_a_tone_curve_is_refused():
    with pytest.raises(SasmiError, match="tone_style needs generator.tone_curve"):
        SasganRun(generator=GeneratorConfig(residual=True, tone_style=True)).validate()


@pytest.mark.parametrize("style", [TONE_STYLE, 0])
def test_the_gray_level_term_spreads_one_render_over_the_real_levels(style):
    """Half the real chips are dark, half bright. From one render, a curve chosen by the render
    alone gives every chip one level: halfway at best. With a code it must learn to give both."""
    torch.manual_seed(0)
    ramp = _ramp(16)
    u = (ramp + 1) / 2  # in [0, 1]
    real_levels = gray_levels(torch.cat([2 * u[:8] ** 3 - 1, 2 * u[8:] ** (1 / 3) - 1]))  # medians −0.75, +0.59
    curve = ToneCurve(style=style)
    optimiser = torch.optim.Adam(curve.parameters(), lr=1e-2)
    for _ in range(300):
        loss = energy_distance(gray_levels(curve(ramp[:8])), real_levels)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        medians = curve(_ramp(64)).flatten(1).median(dim=1).values
    dark, bright = (medians < -0.4).float().mean().item(), (medians > 0.3).float().mean().item()
    if style:
        assert dark > 0.25 and bright > 0.25, (dark, bright)
    else:
        assert min(dark, bright) == 0, (dark, bright)  # one level for all: what the code is for


def test_translate_folder_gives_each_chip_its_own_code_and_the_same_ones_again(tmp_path):
    renders = make_render_set(tmp_path / "renders", n=8, size=16)
    for i in range(1, 8):  # one render eight times: any difference comes from the codes
        (renders / "images" / f"{i:06d}.png").write_bytes((renders / "images" / "000000.png").read_bytes())
    generator = Generator(STYLED).eval().requires_grad_(False)
    _randomise(generator.tone)
    generator.image_size = 16
    translate_folder(generator, renders, tmp_path / "a", batch=4)
    translate_folder(generator, renders, tmp_path / "b", batch=3)
    a = np.stack([read_gray(tmp_path / "a" / "images" / f"{i:06d}.png") for i in range(8)])
    b = np.stack([read_gray(tmp_path / "b" / "images" / f"{i:06d}.png") for i in range(8)])
    np.testing.assert_array_equal(a, b)  # reproducible, whatever the batches
    differs = np.abs(a[:, None] - a[None]).max(axis=(2, 3)) > 1 / 255
    assert differs[~np.eye(8, dtype=bool)].all()  # no two chips share a code, across batches too


def test_a_chip_keeps_its_code_by_its_seed_not_its_place_in_a_batch():
    """`sasmi generate` seeds each chip's code with its scene index: a chip rendered in another
    batch, or by another worker, translates the same; a pose sweep gives every pose one code."""
    generator = Generator(STYLED).eval().requires_grad_(False)
    _randomise(generator.tone)
    generator.image_size = 16
    images = np.random.default_rng(0).random((4, 16, 16)).astype(np.float32)
    together = translate(generator, images, batch=4, seeds=[10, 11, 12, 13])
    alone = translate(generator, images[2:3], batch=1, seeds=[12])
    np.testing.assert_allclose(together[2:3], alone, atol=1e-5)  # batched convs round differently
    same = translate(generator, images[[0, 0]], seeds=[5, 5])
    np.testing.assert_allclose(same[0], same[1], atol=1e-5)
    assert np.abs(together[0] - translate(generator, images[:1], seeds=[11])[0]).max() > 1 / 255


def test_a_styled_sasgan_trains_and_resumes_exactly(tmp_path):
    """The codes come from the run's own stream, kept in its checkpoints: a resumed run draws the same."""
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    cfg = SasganRun(size=32, batch=2, n_critic=1, steps=4, generator=STYLED, critic=CriticConfig(4), levels_weight=1.0,
                    sample_every=100, checkpoint_every=2, ema=0.0)
    a, b = (state["generator"] for state in sasgan_straight_and_resumed(cfg, tmp_path, data))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert any(k.startswith("tone.") and a[k].any() for k in a if k.endswith("weight"))  # the curve trained
