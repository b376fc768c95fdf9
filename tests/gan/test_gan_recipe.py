"""The small-data recipe: each option does what it says, and a test fails if it is ignored."""
import inspect
from dataclasses import replace

import pytest
import torch

from sasmi.gan.augment import AugmentConfig, augment
from sasmi.gan.critic import Critic, CriticConfig
from sasmi.gan.data import ImageSet
from sasmi.gan.generator import GeneratorConfig, load_generator
from sasmi.gan.kinds.common import GanRun, Noise, critic_phase, critic_view
from sasmi.gan.kinds.sasgan import SASGAN, SasganRun
from sasmi.gan.loop import train
from sasmi.eval.config import PreservationConfig
from sasmi.eval.preservation import measure_image
from sasmi.gan.losses import highlight_peaks, mask_contrast_loss, mask_contrasts, r1_penalty, shadow_outline, shadow_shape_loss
from sasmi.labels import TargetLabel
from sasmi.errors import SasmiError
from test_gan_train import toy_gan_inputs

CPU = torch.device("cpu")
SIZE = 32


# ---------------------------------------------------------------- augmentation

def _ramp(batch: int = 16) -> torch.Tensor:
    """(B, 1, S, S): brightness grows along x (range), a bright band at the top (along-track y = 0)."""
    x = torch.linspace(-0.8, 0.8, SIZE).expand(batch, 1, SIZE, SIZE).clone()
    x[:, :, :3] += 0.1
    return x


def test_augment_never_flips_range_but_does_flip_along_track():
    x = _ramp()
    y = augment(x, AugmentConfig(brightness=0.25, contrast=0.3, vflip=True), torch.Generator().manual_seed(0))
    assert (y.mean(dim=(1, 2)).diff(dim=1) > 0).all()  # every image still brightens with range
    top_band = y[:, 0, :3].mean(dim=(1, 2)) > y[:, 0, 3:6].mean(dim=(1, 2))
    assert 0 < top_band.sum() < len(x)  # some flipped up-down, some not
    assert not torch.equal(y, x)


def test_augment_is_differentiable_and_translates_and_cuts_out():
    x = _ramp(4).requires_grad_(True)
    y = augment(x, AugmentConfig(translation=0.125, cutout=0.5), torch.Generator().manual_seed(0))
    assert y.shape == x.shape
    assert all((image == 0).sum() >= 16 * 16 for image in y.detach())  # a 16 px square blanked in each
    y.square().sum().backward()
    assert x.grad.abs().sum() > 0
    assert augment(x, AugmentConfig(), torch.Generator()) is x  # all off: the identity


# ---------------------------------------------------------------- a SAS GAN on toy data

@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return toy_gan_inputs(tmp_path_factory.mktemp("recipe"), SIZE, phi_steps=10)


TOY = SasganRun(size=SIZE, batch=4, n_critic=1, generator=GeneratorConfig(4, 1), critic=CriticConfig(4))


def _phases(data, **overrides):
    cfg = replace(TOY, **overrides)
    torch.manual_seed(cfg.seed)
    return SASGAN.build(cfg.validate(), data, CPU)


def test_the_critic_sees_real_and_fake_through_the_augmentation(data):
    phases = _phases(data, augment=AugmentConfig(cutout=0.5))
    seen = []
    phases.state["critic"].register_forward_pre_hook(lambda module, args: seen.append(args[0].detach()))
    phases.critic_step()  # calls: real and fake in one batch, then the GP interpolates
    phases.generator_step()  # calls: fake
    assert len(seen[0]) == 2 * TOY.batch
    for batch in (seen[0], seen[-1]):
        assert all((image == 0).sum() >= 16 * 16 for image in batch)  # a blanked square in every image


def test_generator_moving_average_is_kept_and_translates(tmp_path, data):
    cfg = replace(TOY, steps=3, ema=0.5, sample_every=100, checkpoint_every=100)
    torch.manual_seed(cfg.seed)
    phases = SASGAN.build(cfg, data, CPU)
    generator, average = phases.state["generator"], phases.state["generator_ema"]
    snapshots = []
    for _ in range(3):
        phases.critic_step()
        phases.generator_step()
        snapshots.append([p.detach().clone() for p in generator.parameters()])
    expected = snapshots[0]  # the first update copies; then decay min(0.5, (1 + n)/(10 + n)), n = 1, 2
    for n, weights in ((1, snapshots[1]), (2, snapshots[2])):
        beta = min(0.5, (1 + n) / (10 + n))
        expected = [e + (w - e) * (1 - beta) for e, w in zip(expected, weights)]
    for e, p in zip(expected, average.module.parameters()):
        torch.testing.assert_close(p, e)

    out = train(SASGAN, cfg, tmp_path / "run", data, CPU).out  # the same 3 steps through the loop
    loaded = load_generator(out)
    for e, p in zip(expected, loaded.parameters()):
        torch.testing.assert_close(p, e)  # translation uses the average, not the last weights
    assert not all(torch.equal(p, q) for p, q in zip(loaded.parameters(), generator.parameters()))


def test_critic_learning_rate_and_ratio_are_options(data):
    phases = _phases(data, lr=2e-3, critic_lr=3e-4, n_critic=3)
    assert phases.state["opt_g"].param_groups[0]["lr"] == 2e-3
    assert phases.state["opt_c"].param_groups[0]["lr"] == 3e-4
    assert phases.critic_steps == 3


# ---------------------------------------------------------------- R1

def test_r1_penalty_of_a_linear_critic_is_its_squared_norm():
    w = torch.randn(1, 1, 8, 8)
    real = torch.randn(3, 1, 8, 8)
    assert torch.isclose(r1_penalty(lambda x: (x * w).sum(dim=(1, 2, 3)), real), w.square().sum())


def _toy_critic(**overrides):
    torch.manual_seed(0)
    rng = torch.Generator().manual_seed(1)

    def stream(mean):
        return lambda: (mean + 0.2 * torch.randn(8, 1, SIZE, SIZE, generator=rng)).clamp(-1, 1)

    critic = Critic(CriticConfig(4), SIZE)
    cfg = replace(GanRun(size=SIZE), **overrides)
    step = critic_phase(cfg, critic, torch.optim.Adam(critic.parameters(), lr=1e-3, betas=(0.5, 0.9)),
                        stream(0.3), stream(-0.3), critic_view(cfg, Noise(2)), Noise(0), CPU)
    for _ in range(40):
        logs = step()
    real = stream(0.3)().requires_grad_(True)
    critic.requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(real).sum(), real)
    return logs, grad.flatten(1).norm(dim=1).mean().item()


def test_r1_regulariser_trains_a_logistic_critic_with_flat_gradients_at_the_reals():
    logs, with_r1 = _toy_critic(regulariser="r1", r1_gamma=10.0)
    assert "loss/r1" in logs and logs["loss/wasserstein"] > 0  # real scores above fake ones
    _, without = _toy_critic(regulariser="r1", r1_gamma=0.0)
    assert with_r1 < 0.5 * without, (with_r1, without)


# ---------------------------------------------------------------- the mask contrast term

def test_mask_contrast_gradient_darkens_shadows_and_brightens_highlights():
    masks = torch.zeros(1, 1, SIZE, SIZE, dtype=torch.uint8)
    masks[..., 10:14, 10:14], masks[..., 10:14, 16:24] = 1, 2  # a target, its shadow to its right
    render = torch.full((1, 1, SIZE, SIZE), -0.3)
    render[masks == 1], render[masks == 2] = 0.8, -0.9
    flat = torch.full_like(render, -0.3).requires_grad_(True)  # a translation that erased both
    loss = mask_contrast_loss(flat, render, masks, keep=0.5, ring=4)
    assert loss > 0
    loss.backward()
    g = flat.grad  # gradient descent moves along −g
    assert (g[masks == 2] > 0).all() and (g[masks == 1] < 0).all()  # shadow down, highlight up
    near_floor = g[(masks == 0) & (g != 0)]
    assert len(near_floor) and (near_floor.sum() != 0)
    assert mask_contrast_loss(render, render, masks, keep=0.5, ring=4) == 0  # the render keeps its own contrast


def test_peak_highlight_term_catches_a_thin_strip_dimmed_into_the_floor():
    # the render's target: a bright 2-px strip on its facing side, the rest of it darker than the
    # floor (its unlit sides); the translation evens the target out just above the floor level,
    # so its mean contrast is kept while nothing on it rises above the floor's speckle (lost)
    masks = torch.zeros(1, 1, SIZE, SIZE, dtype=torch.uint8)
    masks[..., 12:20, 10:16] = 1
    floor = -0.3 + 0.1 * torch.randn(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(0))
    render = torch.where(masks == 1, torch.tensor(-0.6), floor)
    render[..., 12:20, 10:12] = 0.9
    fake = torch.where(masks == 1, torch.tensor(-0.18), floor).requires_grad_(True)
    assert mask_contrast_loss(fake, render, masks, keep=0.5, ring=4) == 0  # the mean term lets it pass
    loss = mask_contrast_loss(fake, render, masks, keep=0.5, ring=4, highlight="peak")
    assert loss > 0.1
    loss.backward()
    assert (fake.grad[masks == 1] < 0).any() and (fake.grad <= 0).all()  # brighten the target, dim nothing
    assert mask_contrast_loss(render, render, masks, keep=0.5, ring=4, highlight="peak") == 0


def test_least_rise_raises_a_target_its_render_left_under_the_speckle():
    # the render's target no brighter than the floor's speckle (lost), so `keep` of its clamped
    # contrast asks only that the translation's rise not be negative; a target that just clears the
    # speckle passes that, and the least rise asks it well out of the speckle all the same
    masks = torch.zeros(1, 1, SIZE, SIZE, dtype=torch.uint8)
    masks[..., 12:20, 10:16] = 1
    floor = -0.3 + 0.1 * torch.randn(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(0))
    render = torch.where(masks == 1, torch.tensor(-0.3), floor)
    speckle = torch.quantile(floor[masks == 0], 0.99)
    fake = torch.where(masks == 1, speckle + 0.05, floor).requires_grad_(True)
    assert highlight_peaks(render, masks) < 0 < highlight_peaks(fake, masks) < 0.3
    assert mask_contrast_loss(fake, render, masks, keep=0.5, ring=4, highlight="peak") == 0
    loss = mask_contrast_loss(fake, render, masks, keep=0.5, ring=4, highlight="peak", least_rise=0.5)
    assert loss > 0.2
    loss.backward()
    assert (fake.grad[masks == 1] < 0).any() and (fake.grad <= 0).all()  # brighten the target, dim nothing
    lit = render.detach().clone()
    lit[..., 14:18, 12:14] = 0.6  # a spot well above the speckle meets it
    assert mask_contrast_loss(lit, render, masks, keep=0.5, ring=4, highlight="peak", least_rise=0.5) == 0


def test_the_run_passes_its_least_rise_to_the_mask_term(data):
    logged = {}
    for rise in (0.0, 1.5):
        phases = _phases(data, mask_weight=1.0, mask_highlight="peak", mask_rise=rise, phi_weight=0.0)
        logged[rise] = phases.generator_step()["loss/mask"]  # same seed: same nets, same batch
    assert logged[1.5] > logged[0.0], logged


def test_the_run_passes_its_highlight_measure_to_the_mask_term(data):
    logged = {}
    for highlight in ("mean", "peak"):
        phases = _phases(data, mask_weight=1.0, mask_highlight=highlight, phi_weight=0.0)
        logged[highlight] = phases.generator_step()["loss/mask"]  # same seed: same nets, same batch
    assert logged["mean"] != logged["peak"], logged


def _shadow_contrast(phases, renders, masks) -> float:
    with torch.no_grad():
        shadow, _ = mask_contrasts(phases.state["generator"](renders), masks, ring=8)
    return shadow.mean().item()


def test_mask_loss_moves_shadows_the_right_way(data):
    images = ImageSet(data["renders"], SIZE, masks=True)
    renders, masks = images.center(list(range(8))), torch.stack(images.masks)  # 48 px renders scaled to 32
    contrast = {}
    for weight in (0.0, 100.0):
        phases = _phases(data, mask_weight=weight, mask_keep=1.0, phi_weight=0.0)
        for _ in range(15):
            phases.generator_step()
        contrast[weight] = _shadow_contrast(phases, renders, masks)
    render_contrast = mask_contrasts(renders, masks, 8)[0].mean().item()
    assert contrast[100.0] > contrast[0.0] + 0.1, contrast  # the term darkens shadows against their floor
    assert contrast[100.0] > 0.3 * render_contrast, (contrast, render_contrast)


def test_mask_loss_needs_masks(tmp_path, data):
    with pytest.raises(SasmiError, match="no masks/"):
        _phases({**data, "renders": data["real"]}, mask_weight=1.0)


# ---------------------------------------------------------------- the shadow shape term

def _shadow_scene(widen: int) -> tuple[torch.Tensor, torch.Tensor]:
    """A render (1, 1, S, S) in [-1, 1] with a target and its shadow, the shadow `widen` px wider
    along track (image y) on each side than its mask, and the mask."""
    masks = torch.zeros(1, 1, SIZE, SIZE, dtype=torch.uint8)
    masks[..., 12:18, 8:12], masks[..., 12:18, 12:24] = 1, 2
    image = -0.2 + 0.05 * torch.randn(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(1))
    image[masks == 1] = 0.8
    image[..., 12 - widen:18 + widen, 12:24] = -0.9
    return image, masks


def _measured_iou(image: torch.Tensor, masks: torch.Tensor) -> float:
    """The evaluation's shadow IoU (sasmi/eval/preservation.py) of one signed image."""
    target = TargetLabel(params={"shape": "box"}, pixel_centre=(9.5, 14.5), bbox=(8, 12, 12, 18), shadow_bbox=(12, 12, 24, 18))
    return measure_image(((image[0, 0] + 1) / 2).detach().numpy(), masks[0, 0].numpy(), [target])["shadow_iou"]


def test_dark_floor_beside_a_shadow_grows_as_the_evaluations_shadow_iou_falls():
    masks = _shadow_scene(0)[1]
    beside = [shadow_outline(_shadow_scene(w)[0], masks, ring=4)[0].item() for w in (0, 2, 4)]
    iou = [_measured_iou(_shadow_scene(w)[0], masks) for w in (0, 2, 4)]
    assert beside[0] < 0.1 < beside[1] < beside[2] and iou[0] > iou[1] > iou[2], (beside, iou)
    assert 1.0 < beside[2] < 1.6, beside  # 2 × 4 rows of 12 px beside a 6 × 12 px shadow: 4 / 3 of its area
    assert all(torch.isnan(x).all() for x in shadow_outline(_shadow_scene(0)[0], torch.zeros_like(masks), ring=4))
    # the term's "dark" is the evaluation's: the same blur and threshold (gan/ does not import sasmi.eval)
    defaults = inspect.signature(shadow_outline).parameters
    assert (defaults["smooth"].default, defaults["dark_fraction"].default) == \
        (PreservationConfig.smooth, PreservationConfig.dark_fraction)


def test_shadow_shape_term_narrows_a_widened_shadow_and_darkens_nothing():
    render, masks = _shadow_scene(0)
    widened = _shadow_scene(3)[0]
    assert shadow_shape_loss(render, render, masks, ring=4) == 0  # the render keeps its own shape
    fake = widened.clone().requires_grad_(True)
    shadow_shape_loss(fake, render, masks, ring=4).backward()
    assert (fake.grad <= 0).all()  # gradient descent brightens; nothing is darkened
    # plain steps: Adam's per-pixel scaling would move the shadow's edge, whose gradient through the blur is
    # tiny, as far as the floor beside it
    optimiser = torch.optim.SGD([fake], lr=1.0)
    for _ in range(30):
        optimiser.zero_grad()
        shadow_shape_loss(fake, render, masks, ring=4).backward()
        optimiser.step()
    before, after = _measured_iou(widened, masks), _measured_iou(fake, masks)
    assert after > before + 0.2, (before, after)
    assert fake.detach()[masks == 2].mean() < -0.5  # the shadow itself stays dark


def test_shadow_shape_term_darkens_a_shadow_paled_above_the_dark_threshold():
    render, masks = _shadow_scene(0)
    pale = render.clone()
    pale[masks == 2] = -0.5  # 0.25 in [0, 1] on a floor at 0.4: above half of it, no longer "dark"
    pale.requires_grad_(True)
    loss = shadow_shape_loss(pale, render, masks, ring=4)
    assert loss > 0.5, loss
    loss.backward()
    assert (pale.grad[masks == 2] > 0).all()  # gradient descent darkens the shadow


def test_shadow_shape_term_pulls_an_overdone_shadow_back_to_its_render():
    # hinges are met with a margin: the generator learns shadows darker than the render's and a
    # bright rim beside them. Each change here lies beyond the blur's reach (4 px) of
    # the other side of the shadow's edge, so that only a two-sided term sees it
    masks = torch.zeros(1, 1, SIZE, SIZE, dtype=torch.uint8)
    masks[..., 8:24, 8:12], masks[..., 8:24, 12:28] = 1, 2  # a 16 × 16 px shadow
    render = -0.2 + 0.05 * torch.randn(1, 1, SIZE, SIZE, generator=torch.Generator().manual_seed(1))
    render[masks == 1], render[masks == 2] = 0.8, -0.75  # the shadow at 0.3 of the floor: partly "pale"
    darker, rim = render.clone(), render.clone()
    darker[..., 13:19, 17:23] = -0.95  # the shadow's core darker than the render's
    rim[..., 1:3, 12:28] = rim[..., 29:31, 12:28] = 0.3  # a bright rim on the floor 5 px beside it
    for fake in (darker, rim):
        fake.requires_grad_(True)
        loss = shadow_shape_loss(fake, render, masks, ring=8)
        assert loss > 0.001, loss
        loss.backward()
    assert (darker.grad[..., 13:19, 17:23] < 0).all()  # gradient descent brightens the shadow
    assert (rim.grad[..., 1:3, 12:28] > 0).all() and (rim.grad[..., 29:31, 12:28] > 0).all()  # darkens the rim


def test_the_run_applies_its_shadow_shape_term(data):
    images = ImageSet(data["renders"], SIZE, masks=True)
    renders, masks = images.center(list(range(8))), torch.stack(images.masks)
    beside = {}
    for weight in (0.0, 100.0):
        phases = _phases(data, shadow_weight=weight, phi_weight=0.0)
        for _ in range(15):
            logs = phases.generator_step()
        with torch.no_grad():
            beside[weight] = shadow_outline(phases.state["generator"](renders), masks, ring=8)[0].nanmean().item()
    assert "loss/shadow_shape" in logs and "loss/mask" not in logs
    assert beside[100.0] < beside[0.0] - 0.1, beside
    with pytest.raises(SasmiError, match="shadow_weight"):
        replace(TOY, shadow_weight=-1.0).validate()


def test_recipe_flags_from_the_command_line(tmp_path, data):
    from sasmi.cli.main import main

    out = tmp_path / "run"
    assert main(["train", "sasgan", "--real", str(data["real"]), "--renders", str(data["renders"]), "--phi",
                 str(data["phi"]), "--out", str(out), "--size", "32", "--batch", "2", "--steps", "2", "--n-critic", "1",
                 "--device", "cpu", "--augment", "--regulariser", "r1", "--r1-gamma", "0.5", "--critic-lr", "1e-4",
                 "--ema", "0.9", "--mask-weight", "10", "--mask-keep", "0.7", "--patch-critic", "--residual"]) == 0
    config = torch.load(out / "checkpoints" / "last.pt", weights_only=True)["config"]
    assert config["augment"] == AugmentConfig.recommended().__dict__
    assert config["critic"]["patch"] and config["generator"]["residual"]
    assert (config["regulariser"], config["r1_gamma"], config["critic_lr"], config["ema"], config["mask_weight"],
            config["mask_keep"]) == ("r1", 0.5, 1e-4, 0.9, 10.0, 0.7)
