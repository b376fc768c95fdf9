"""Gray levels: the generator's tone curve (monotone, the identity at first, one per chip) and the
gray-level term (an energy distance between per-chip level distributions) that moves them toward real."""
import pytest
import torch

from sasmi.errors import SasmiError
from sasmi.gan.critic import CriticConfig
from sasmi.gan.data import ImageSet
from sasmi.gan.generator import RENDER_REACH, Generator, GeneratorConfig, ToneCurve
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.losses import energy_distance, gray_levels
from test_gan_train import toy_gan_inputs

SIZE = 32


def _chips(levels: list[float], size: int = 16) -> torch.Tensor:
    """(B, 1, S, S) in [-1, 1]: speckle-like chips around the given mean levels."""
    g = torch.Generator().manual_seed(0)
    return torch.stack([(m + 0.2 * torch.randn(1, size, size, generator=g)).clamp(-1, 1) for m in levels])


def test_tone_curve_starts_as_the_identity_and_stays_monotone_within_range():
    curve = ToneCurve()
    x = _chips([-0.6, 0.0, 0.5])
    torch.testing.assert_close(curve(x), x)
    generator = Generator(GeneratorConfig(4, 1, residual=True, correction_scale=4, tone_curve=True))
    torch.testing.assert_close(generator(x), x.clamp(-RENDER_REACH, RENDER_REACH))  # training starts at the render
    flat = torch.full((1, 1, 8, 8), -1.0)
    flat[..., 4:] = 0.2  # two levels only: many knots tie, and the curve must still be the identity
    torch.testing.assert_close(curve(flat), flat, atol=1e-3, rtol=0)

    torch.manual_seed(1)
    for p in curve.parameters():
        torch.nn.init.normal_(p, std=3.0)  # any weights
    levels, targets = curve.knots(x)
    assert (levels.diff(dim=1) >= 0).all() and (targets.diff(dim=1) >= 0).all()  # never decreasing
    assert targets.min() >= -1 and targets.max() <= 1
    y = curve(x)
    order = x.flatten(1).argsort(dim=1)
    assert (y.flatten(1).gather(1, order).diff(dim=1) >= -1e-6).all()  # order of gray levels is kept: only levels change
    assert y.min() >= -1 and y.max() <= 1


def test_tone_curve_knots_sit_where_the_pixels_are():
    """A dark chip (nine tenths of it below −0.6, as SAS chips are) can be reshaped within its dark
    part: a curve may spread its darkest tenth apart from the next without moving the bright ones."""
    x = _chips([-0.8])
    levels, _ = ToneCurve().knots(x)
    assert (levels[0, 1:-1] < -0.4).float().mean() > 0.8  # most knots among the dark pixels, not evenly over [-1, 1]


def test_each_chip_gets_its_own_curve_from_its_gray_levels():
    """Dark chips must be brightened and bright ones darkened to one level: no single curve can
    do both (it would have to map the same gray level two ways), a per-chip one can."""
    chips = _chips([-0.6, -0.5, 0.3, 0.4])
    target = chips - chips.mean(dim=(1, 2, 3), keepdim=True)  # every chip centred on 0
    torch.manual_seed(0)
    curve = ToneCurve()
    optimiser = torch.optim.Adam(curve.parameters(), lr=1e-2)
    for _ in range(300):
        loss = ((curve(chips) - target) ** 2).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    means = curve(chips).mean(dim=(1, 2, 3))
    assert means.abs().max() < 0.1, means  # dark chips raised, bright ones lowered, all near 0
    assert (means[:2] - chips[:2].mean(dim=(1, 2, 3)) > 0.3).all() and (means[2:] < chips[2:].mean(dim=(1, 2, 3)) - 0.2).all()


def test_tone_curve_and_gray_level_settings_that_cannot_work_are_refused():
    with pytest.raises(SasmiError, match="tone_curve"):
        SasganRun(generator=GeneratorConfig(tone_curve=True)).validate()
    with pytest.raises(SasmiError, match="levels_weight.*--batch 2"):
        SasganRun(levels_weight=1.0, batch=1).validate()


def test_energy_distance_closed_form_and_zero_for_one_distribution():
    x, y = torch.tensor([[0.0], [1.0]]), torch.tensor([[2.0], [3.0]])
    # 2 · mean |x − y| (2, 3, 1, 2 → 2) − |0 − 1| − |2 − 3|
    assert energy_distance(x, y).item() == pytest.approx(2.0)
    assert energy_distance(x, y) == energy_distance(y, x)
    g = torch.Generator().manual_seed(0)
    a, b = torch.randn(400, 5, generator=g), torch.randn(400, 5, generator=g)
    assert abs(energy_distance(a, b).item()) < 0.02
    assert energy_distance(a + 0.5, b).item() > 0.2


def test_gray_levels_are_ordered_quantiles_with_gradients():
    x = (torch.rand(3, 1, SIZE, SIZE) * 2 - 1).requires_grad_(True)
    levels = gray_levels(x)
    assert levels.shape == (3, 27) and (levels.diff(dim=1) >= 0).all()
    levels[:, -1].sum().backward()  # the bright tail reaches the brightest pixels
    assert x.grad.abs().sum() > 0


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return toy_gan_inputs(tmp_path_factory.mktemp("levels"), SIZE, phi_steps=5)


def test_gray_level_term_brings_the_image_to_the_real_levels_through_the_curve_alone(data):
    """The toy renders are a flat 0.35 floor; the real chips a skewed gamma speckle. A fixed
    correction that brightens everything stands for what the critic asks of the spatial net. The
    term must bring the levels the image ends with to real (the curve makes room for the
    correction) and train the curve alone: asked of the whole generator, the correction meets it by
    painting bright bands beside the shadows; asked of the curve's output, it misses the levels that
    the correction then moves."""
    renders = ImageSet(data["renders"], SIZE).center(list(range(8)))
    real = ImageSet(data["real"], SIZE)
    real_levels = gray_levels(real.center(list(range(len(real)))))
    torch.manual_seed(0)
    generator = Generator(GeneratorConfig(4, 1, residual=True, correction_scale=4, tone_curve=True))
    torch.nn.init.constant_(generator.net[-1].bias, 0.5)  # + 0.5 in atanh units everywhere
    start = energy_distance(gray_levels(generator(renders)), real_levels).item()
    optimiser = torch.optim.Adam(generator.tone.parameters(), lr=1e-2)
    for _ in range(150):
        term = energy_distance(gray_levels(generator(renders, parts=True).curve_only), real_levels)
        optimiser.zero_grad()
        term.backward()
        optimiser.step()
    with torch.no_grad():
        image, curve_only, _ = generator(renders, parts=True)
    torch.testing.assert_close(curve_only, image)  # the term sees the image itself
    end = energy_distance(gray_levels(image), real_levels).item()
    assert end < 0.1 * start, (start, end)

    generator.zero_grad()
    energy_distance(gray_levels(generator(renders, parts=True).curve_only), real_levels).backward()
    assert all(p.grad is None or not p.grad.any() for p in generator.net.parameters())
    assert any(p.grad is not None and p.grad.any() for p in generator.tone.parameters())


def test_gray_level_term_with_one_real_chip_is_refused(tmp_path, data):
    import shutil

    one = tmp_path / "one"
    one.mkdir()
    shutil.copy(sorted(data["real"].glob("*.png"))[0], one)
    cfg = SasganRun(size=SIZE, batch=2, critic=CriticConfig(4), levels_weight=1.0,
                    generator=GeneratorConfig(4, 1, residual=True, correction_scale=4, tone_curve=True))
    with pytest.raises(SasmiError, match="2 real chips"):
        SASGAN.build(cfg.validate(), {**data, "real": one}, torch.device("cpu"))


def test_energy_distance_in_row_blocks_equals_the_whole_matrix(monkeypatch):
    """Large sets (the evaluation's 20000 chips) are summed a block of rows at a time."""
    import sasmi.gan.losses as losses

    g = torch.Generator().manual_seed(3)
    x, y = torch.randn(11, 4, generator=g), torch.randn(7, 4, generator=g) + 0.3
    whole = energy_distance(x, y)
    monkeypatch.setattr(losses, "DISTANCE_ROWS", 3)
    assert energy_distance(x, y).item() == pytest.approx(whole.item(), abs=1e-5)


def test_a_standardised_critic_does_not_see_a_chips_level_or_contrast():
    """[critic] standardise leaves the overall level and contrast to the gray-level term: the
    same picture at another level and contrast scores the same; the picture itself still counts."""
    from sasmi.gan.critic import Critic

    x = _chips([-0.5, 0.1], size=SIZE)
    torch.manual_seed(0)
    blind = Critic(CriticConfig(4, standardise=True), SIZE)
    torch.testing.assert_close(blind(0.5 * x + 0.2), blind(x), atol=1e-5, rtol=1e-4)
    assert (blind(x.flip(-1)) - blind(x)).abs().min() > 1e-4  # what is where still matters
    seeing = Critic(CriticConfig(4), SIZE)
    seeing.load_state_dict(blind.state_dict())
    assert (seeing(0.5 * x + 0.2) - seeing(x)).abs().min() > 1e-4

    flat = torch.zeros(1, 1, SIZE, SIZE, requires_grad=True)  # a flat chip: the penalty's gradient stays finite
    blind(flat).sum().backward()
    assert torch.isfinite(flat.grad).all()
    with pytest.raises(SasmiError, match="standardise"):
        SasganRun(critic=CriticConfig(phi_features=True, standardise=True)).validate()
