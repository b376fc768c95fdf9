"""Donor levels: each translated chip takes the gray-level distribution of a real chip the GAN
learned from, drawn by its code, while every pixel keeps the rank the generator gave it; the
real chips' levels travel in the run's checkpoint, so translation draws from the same chips."""
from dataclasses import replace

import numpy as np
import pytest
import torch

import sasmi.gan.kinds.sasgan

from sasmi.errors import SasmiError
from sasmi.gan.critic import CriticConfig
from sasmi.gan.generator import DONOR_PROBS, _RanksOnly, Generator, GeneratorConfig, donor_index, load_generator
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.translate import translate
from sasmi.gan.recipes import load_recipe
from sasmi.gan.loop import train
from test_gan_train import CPU, toy_gan_inputs

DONOR = GeneratorConfig(4, 1, residual=True, correction_scale=4, donor_levels=True)
AFTER = GeneratorConfig(4, 1, residual=True, correction_scale=4, donor_levels_after=True)


def _generator_with_donors(real: torch.Tensor) -> Generator:
    torch.manual_seed(0)
    generator = Generator(DONOR)
    torch.nn.init.normal_(generator.net[-1].weight, std=0.3)  # a correction that does something
    generator.set_donors(real)
    return generator


def _real(n: int = 4, size: int = 32) -> torch.Tensor:
    """(n, 1, S, S) in [-1, 1], each chip a different distribution: dark to bright."""
    u = torch.rand(n, 1, size, size, generator=torch.Generator().manual_seed(1))
    return torch.stack([2 * u[i] ** (3.0 / (i + 1)) - 1 for i in range(n)])


def test_each_chip_takes_the_chosen_real_chips_levels_and_keeps_its_ranks():
    real = _real()
    generator = _generator_with_donors(real)
    renders = torch.rand(4, 1, 32, 32, generator=torch.Generator().manual_seed(2)) * 0.6 - 0.8
    code = torch.tensor([[-2.0], [-0.3], [0.3], [2.0]])  # one per donor
    with torch.no_grad():
        chips, _, own_levels = generator(renders, code=code, parts=True)
    assert donor_index(code[:, 0], 4).tolist() == [0, 1, 2, 3]
    for chip, own, donor in zip(chips, own_levels, real):
        probs = torch.linspace(0, 1, 21)
        torch.testing.assert_close(chip.flatten().quantile(probs), donor.flatten().quantile(probs), atol=0.02, rtol=0)
        order = own.flatten().argsort()
        assert (chip.flatten()[order].diff() >= -1e-6).all()  # brighter stays brighter
    assert (chips - own_levels).abs().max() > 0.1  # the levels did change


def test_the_gradient_moves_ranks_only():
    """The net cannot change a donor's levels, only each pixel's rank: the gradient passes straight
    through the matching, less its parts along a shift or a stretch of the chip's own levels, which
    keep every rank (left in, those add up until the net's own levels sit at ±1 and the chips
    go flat)."""
    generator = _generator_with_donors(_real())
    renders = torch.rand(2, 1, 32, 32, generator=torch.Generator().manual_seed(3)) * 0.6 - 0.8
    code = torch.zeros(2, 1)
    own = generator(renders, code=code, parts=True).own_levels.detach().requires_grad_(True)
    matched = _RanksOnly.apply(own, generator.at_donor_levels(own.detach(), code))
    torch.testing.assert_close(matched, generator(renders, code=code))
    (matched * torch.randn(2, 1, 32, 32)).sum().backward()
    centred = own.detach() - own.detach().mean(dim=(1, 2, 3), keepdim=True)
    assert own.grad.sum(dim=(1, 2, 3)).abs().max() < 1e-4  # no shift
    assert (own.grad * centred).sum(dim=(1, 2, 3)).abs().max() < 1e-4  # no stretch
    assert own.grad.abs().mean() > 0.5  # the rest passes


@pytest.mark.parametrize("generator_cfg", [DONOR, AFTER])
def test_the_donors_travel_in_the_checkpoint_and_a_seed_picks_the_same_one(tmp_path, generator_cfg):
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    cfg = SasganRun(size=32, batch=2, n_critic=1, steps=2, generator=generator_cfg, critic=CriticConfig(4),
                    sample_every=100, checkpoint_every=2)
    run = train(SASGAN, cfg, tmp_path / "run", data, CPU).out
    generator = load_generator(run)  # the moving average, its donors copied with it
    assert generator.donors.shape == (8, len(DONOR_PROBS))  # the toy set's 8 real chips
    renders = np.random.default_rng(0).random((3, 32, 32)).astype(np.float32) * 0.5
    out = translate(generator, renders[[0, 0, 0]], seeds=[7, 7, 8])
    np.testing.assert_array_equal(out[0], out[1])
    levels = torch.quantile(torch.from_numpy(out * 2 - 1).flatten(1), DONOR_PROBS, dim=1).T
    nearest = torch.cdist(levels, generator.donors).min(dim=1).values
    assert (nearest < 0.1).all(), nearest  # each output is one of the real chips' distributions


@pytest.mark.parametrize("other", [{"generator": GeneratorConfig(residual=True, tone_curve=True, donor_levels=True)},
                                   {"generator": DONOR, "levels_weight": 1.0},
                                   {"generator": GeneratorConfig(residual=True, donor_levels=True,
                                                                 donor_levels_after=True)},
                                   {"generator": GeneratorConfig(residual=True, donor_shadow=0.4)}])
def test_donor_levels_refuse_the_other_ways_of_choosing_levels(other):
    with pytest.raises(SasmiError, match="donor_levels"):
        SasganRun(**other).validate()


def test_a_runs_sample_grids_use_fixed_codes(tmp_path):
    """Grids drawn with fresh codes would differ in gray levels from one to the next."""
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    cfg = SasganRun(size=32, batch=2, n_critic=1, steps=2, generator=DONOR, critic=CriticConfig(4))
    phases = SASGAN.build(cfg, data, CPU)
    first, second = phases.samples(), phases.samples()
    torch.testing.assert_close(first[1], second[1])


def test_the_content_terms_compare_the_chip_with_the_render_at_the_same_donors_levels(tmp_path):
    """At the first step the residual generator gives back the render at a donor's levels: the φ
    and mask terms must see no change (against the render itself, the levels alone would count)."""
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    cfg = SasganRun(size=32, batch=2, n_critic=1, steps=2, generator=DONOR, critic=CriticConfig(4),
                    phi_margin=0.0, mask_weight=1.0, mask_keep=1.0)
    logs = SASGAN.build(cfg, data, CPU).generator_step()
    assert logs["loss/phi"] < 1e-6 and logs["loss/mask"] < 1e-6, logs


def test_the_nets_own_levels_are_held_at_the_renders(tmp_path, monkeypatch):
    """The donor's levels replace the net's own, so nothing else holds those: an anchor does."""
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    cfg = SasganRun(size=32, batch=2, n_critic=1, steps=2, generator=DONOR, critic=CriticConfig(4), lr=0.05)

    def anchor_after_a_push(weight: float) -> tuple[float, float]:
        monkeypatch.setattr(sasmi.gan.kinds.sasgan, "DONOR_ANCHOR", weight)
        torch.manual_seed(0)
        phases = SASGAN.build(cfg, data, CPU)
        assert phases.generator_step()["loss/anchor"] < 1e-6  # the render itself at first
        torch.nn.init.constant_(phases.state["generator"].net[-1].bias, 1.0)  # + 1 in atanh units everywhere
        first = phases.generator_step()["loss/anchor"]
        for _ in range(60):
            last = phases.generator_step()["loss/anchor"]
        return first, last

    (first, held), (_, free) = anchor_after_a_push(10.0), anchor_after_a_push(0.0)
    assert first > 0.1 and held < 0.5 * free, (first, held, free)


def test_after_the_critic_sees_the_nets_own_levels_and_translation_a_donors():
    """`donor_levels_after`: the GAN trains as without donors; in eval mode (translation, the
    sample grids) each chip takes a donor's levels."""
    real = _real()
    torch.manual_seed(0)
    generator = Generator(AFTER)
    torch.nn.init.normal_(generator.net[-1].weight, std=0.3)
    generator.set_donors(real)
    plain = Generator(GeneratorConfig(4, 1, residual=True, correction_scale=4))
    plain.load_state_dict({k: v for k, v in generator.state_dict().items() if k != "donors"})
    renders = torch.rand(4, 1, 32, 32, generator=torch.Generator().manual_seed(2)) * 0.6 - 0.8
    code = torch.tensor([[-2.0], [-0.3], [0.3], [2.0]])
    with torch.no_grad():
        torch.testing.assert_close(generator.train()(renders, code=code), plain(renders))
        translated = generator.eval()(renders, code=code)
    probs = torch.linspace(0, 1, 21)
    for chip, donor in zip(translated, real):
        torch.testing.assert_close(chip.flatten().quantile(probs), donor.flatten().quantile(probs), atol=0.02, rtol=0)


def _chip_with_shadow(size: int = 32) -> torch.Tensor:
    """(1, 1, S, S) in [-1, 1]: a speckled floor of intensity about 0.4 and a 6 × 10 px shadow at 0.02."""
    u = 0.4 * (0.75 + 0.5 * torch.rand(1, 1, size, size, generator=torch.Generator().manual_seed(3)))
    u[..., 12:18, 10:20] = 0.02
    return u * 2 - 1


def test_donor_shadow_keeps_the_shadow_as_dark_against_the_floor_as_it_was():
    """A donor whose darkest levels are pale (0.2 of full scale, where the floor's median is 0.5)
    would give the shadow a ratio of 0.4 to the floor; with `donor_shadow` it keeps its own, 0.05."""
    chip = _chip_with_shadow()
    pale = torch.linspace(0.2, 0.8, 32 * 32).view(1, 1, 32, 32) * 2 - 1
    matched = {}
    for fraction in (0.0, 0.4):
        generator = Generator(replace(AFTER, donor_shadow=fraction)).eval()
        generator.set_donors(pale)
        matched[fraction] = (generator.at_donor_levels(chip, torch.zeros(1, 1)) + 1) / 2  # (1, 1, S, S) in [0, 1]

    def shadow_to_floor(u: torch.Tensor) -> float:
        return float(u[..., 13:17, 11:19].mean() / u.median())

    assert shadow_to_floor((chip + 1) / 2) == pytest.approx(0.05, abs=0.01)
    assert shadow_to_floor(matched[0.0]) > 0.35  # the plain match: the donor's pale darkest levels
    assert shadow_to_floor(matched[0.4]) == pytest.approx(0.05, abs=0.01)
    assert torch.equal(matched[0.4][..., 24:, :], matched[0.0][..., 24:, :])  # the floor takes the donor's levels


def test_after_trains_the_very_same_generator(tmp_path):
    """The donors' levels come after training: the weights are those of the same run without them."""
    data = toy_gan_inputs(tmp_path / "data", 32, phi_steps=5)
    base = SasganRun(size=32, batch=2, n_critic=1, steps=3, critic=CriticConfig(4), sample_every=100, checkpoint_every=3,
                     generator=GeneratorConfig(4, 1, residual=True, correction_scale=4))
    states = [torch.load(train(SASGAN, cfg, tmp_path / name, data, CPU).out / "checkpoints" / "last.pt",
                         weights_only=True)["state"]["generator"]
              for name, cfg in (("plain", base), ("after", replace(base, generator=AFTER)))]
    assert set(states[1]) - set(states[0]) == {"donors"}
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])


def test_the_real_levels_recipe_is_small_data_with_donors_after_and_a_coarser_correction():
    """Two files that must not drift apart: the only differences are the donors' levels and the correction's scale."""
    small, real = load_recipe("small_data"), load_recipe("real_levels")
    assert real.pop("generator") == replace(small.pop("generator"), donor_levels_after=True, donor_shadow=0.4,
                                            correction_scale=16)
    assert real == small
