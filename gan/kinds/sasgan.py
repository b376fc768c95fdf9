"""The SAS GAN run: render → realistic image, an adversarial critic + the φ constraint (Reed et al.)
+ the small-data recipe: critic augmentation, a generator moving average, mask contrast and shadow shape terms."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from torch.optim.swa_utils import AveragedModel

from sasmi.gan.autoencoder import load_encoder
from sasmi.gan.critic import make_critic
from sasmi.gan.data import Batches, ImageSet
from sasmi.gan.distributed import parallel
from sasmi.gan.generator import Generator, GeneratorConfig
from sasmi.gan.kinds.common import (GanRun, Noise, adam, adversarial_loss, before_after, critic_phase, critic_view,
                              grad_norm, spread)
from sasmi.gan.loop import Kind, Logs, Phases
from sasmi.gan.losses import energy_distance, gray_levels, mask_contrast_loss, phi_loss, shadow_shape_loss
from sasmi.gan.run import check_number, file_fingerprint
from sasmi.errors import SasmiError


@dataclass(frozen=True)
class SasganRun(GanRun):
    generator: GeneratorConfig = GeneratorConfig()
    phi_weight: float = 100.0  # at 10 the adversarial term wins and content is lost (docs/gan.md)
    phi_margin: float = 0.25  # γ: φ(G(render)) may move this fraction of ‖φ(render)‖ for free (docs/gan.md)
    ema: float = 0.999  # decay of the generator's moving average that translates (0: none); ramped in early on
    mask_weight: float = 0.0  # weight of the mask contrast term (needs the renders' masks/); 0: off
    mask_keep: float = 0.5  # fraction of a render's shadow/highlight contrast the translation must keep
    mask_ring: int = 8  # px around a shadow or target that count as its surrounding floor (at S)
    mask_highlight: str = "mean"  # "peak": keep the target's brightest spot above the floor's speckle instead
    mask_rise: float = 0.0  # the least highlight contrast asked of every target (signed units), its render's aside
    shadow_weight: float = 0.0  # weight of the shadow shape term (needs masks/): the render's shadow outline, no wider or narrower, no paler or darker
    # weight of the gray-level term: the energy distance between the translations' per-chip gray-level
    # distributions (quantiles, tail included) and the real chips' (0: off); with the tone curve it
    # judges the whole image and trains the curve alone to meet it. A critic that learns from ~100
    # chips does not see the levels
    levels_weight: float = 0.0

    def validate(self) -> "SasganRun":
        super().validate()
        check_number("--phi-weight", self.phi_weight)
        check_number("--phi-margin", self.phi_margin)
        check_number("--ema", self.ema)
        check_number("--mask-weight", self.mask_weight)
        check_number("--mask-keep", self.mask_keep)
        check_number("mask_rise", self.mask_rise)
        check_number("shadow_weight", self.shadow_weight)
        check_number("levels_weight", self.levels_weight)
        if self.levels_weight > 0 and self.batch < 2:
            raise SasmiError(f"levels_weight = {self.levels_weight:g} compares the chips of a batch: needs --batch 2 or more")
        check_number("mask_ring", self.mask_ring, high=self.size // 2)
        if self.mask_highlight not in ("mean", "peak"):
            raise SasmiError(f"mask_highlight = {self.mask_highlight!r}: choose \"mean\" or \"peak\"")
        scale = self.generator.correction_scale
        check_number("generator.correction_scale", scale)
        if self.generator.tone_curve and not self.generator.residual:
            raise SasmiError("generator.tone_curve needs generator.residual = true (the curve remaps the render)")
        if self.generator.tone_style and not self.generator.tone_curve:
            raise SasmiError("generator.tone_style needs generator.tone_curve = true (the code chooses the curve)")
        donor = self.generator.takes_donors
        if donor and (self.generator.tone_curve or self.levels_weight > 0):
            raise SasmiError("generator.donor_levels(_after) gives each chip a real chip's gray levels: it replaces "
                             "generator.tone_curve and levels_weight (turn those off)")
        check_number("generator.donor_shadow", self.generator.donor_shadow)
        if self.generator.donor_shadow and not donor:
            raise SasmiError("generator.donor_shadow keeps shadows through a donor's levels: needs "
                             "generator.donor_levels or donor_levels_after")
        if self.generator.donor_levels and self.generator.donor_levels_after:
            raise SasmiError("generator.donor_levels and donor_levels_after: choose one (learned, or in "
                             "translation only)")
        if scale > 1 and (not self.generator.residual or self.size % scale):
            raise SasmiError(f"generator.correction_scale = {scale}: needs generator.residual = true and a --size "
                             f"that it divides ({self.size})")
        return self


DONOR_ANCHOR = 10.0  # weight of the anchor of the net's own levels with donor levels; as the mask term's


def moving_average(generator: Generator, decay: float) -> AveragedModel:
    """An exponential moving average of the generator's weights, its decay ramped up as
    (1 + n)/(10 + n) over the first updates so that the random initialisation fades fast."""

    def average(avg: torch.Tensor, new: torch.Tensor, n: torch.Tensor) -> torch.Tensor:
        beta = min(decay, (1.0 + float(n)) / (10.0 + float(n)))
        return avg + (new - avg) * (1.0 - beta)

    return AveragedModel(generator, avg_fn=average, use_buffers=True)


def build(cfg: SasganRun, inputs: dict[str, Path], device: torch.device) -> Phases:
    # ---- data and the frozen φ encoder
    real = ImageSet(inputs["real"], cfg.size)
    renders = ImageSet(inputs["renders"], cfg.size, masks=cfg.mask_weight > 0 or cfg.shadow_weight > 0)
    real_batches = Batches(real, cfg.batch, seed=cfg.seed)
    render_batches = Batches(renders, cfg.batch, seed=cfg.seed + 1)
    noise, view_noise, style_noise = Noise(cfg.seed + 2), Noise(cfg.seed + 4), Noise(cfg.seed + 5)
    fixed = renders.center(spread(len(renders), 8)).to(device)  # (n, 1, S, S) in [-1, 1]
    if cfg.levels_weight > 0:
        if len(real) < 2:
            raise SasmiError(f"--real {inputs['real']}: the gray-level term (levels_weight) needs 2 real chips or more")
        real_levels = gray_levels(real.center(list(range(len(real))))).to(device)  # (N, 27): every real chip's levels
    encoder = load_encoder(inputs["phi"], device)  # (B, 1, S, S) in [-1, 1] → (B, 1024)
    if encoder.image_size != cfg.size:
        raise SasmiError(f"--phi {inputs['phi']}: the autoencoder was trained at {encoder.image_size} px; "
                         f"train the SAS GAN with --size {encoder.image_size} (or retrain it at {cfg.size})")

    # ---- models and optimisers
    generator = Generator(cfg.generator).to(device)
    if cfg.generator.takes_donors:  # before the moving average copies it
        generator.set_donors(real.center(list(range(len(real)))).to(device))
    # (n, style_size) ~ N(0, 1): the sample grids' own codes, so that a run's grids compare step to step
    fixed_code = torch.randn(len(fixed), generator.style_size, generator=torch.Generator().manual_seed(cfg.seed))
    critic = make_critic(cfg.critic, cfg.size, encoder).to(device)
    average = moving_average(generator, cfg.ema) if cfg.ema > 0 else None
    opt_g = adam(generator.parameters(), cfg.lr, cfg)
    opt_c = adam(critic.parameters(), cfg.critic_lr or cfg.lr, cfg)
    view = critic_view(cfg, view_noise)  # real and fake alike
    # what trains: across processes their gradients are averaged (gan/distributed.py); the
    # critic that only passes gradients to the generator, and the no-grad fakes, need no wrapper
    train_generator, train_critic = parallel(generator), parallel(critic)

    def render_batch() -> tuple[torch.Tensor, torch.Tensor | None]:
        x, masks = render_batches.next_with_masks()  # (B, 1, S, S) in [-1, 1]; uint8 labels or None
        return x.to(device), None if masks is None else masks.to(device)

    def style_code(n: int) -> torch.Tensor | None:
        # (n, style_size) ~ N(0, 1) from the run's own stream, so that a resumed run draws the same
        return style_noise.normal(n, generator.style_size).to(device) if generator.style_size else None

    def critic_fake() -> torch.Tensor:
        render = render_batch()[0]
        return generator(render, code=style_code(len(render)))

    critic_step = critic_phase(cfg, train_critic, opt_c, lambda: real_batches.next().to(device),
                               critic_fake, view, noise, device)

    def generator_step() -> Logs:
        """Fool the critic while φ(G(render)) stays within γ of φ(render) and the mask contrasts stay."""
        render, masks = render_batch()
        code = style_code(len(render))
        drawn = train_generator(render, code=code, parts=True)  # (B, 1, S, S) in [-1, 1] each
        fake = drawn.image
        adversarial = adversarial_loss(cfg, critic(view(fake)))
        # what the content terms compare the chip with: the render itself, or, with donor levels, the
        # render given the same donor's levels (the levels the net cannot change; they move φ)
        reference = generator.at_donor_levels(render, code) if cfg.generator.donor_levels else render
        with torch.no_grad():
            phi_render = encoder(reference)  # (B, 1024): a target, no gradient needed
        constraint = phi_loss(phi_render, encoder(fake), cfg.phi_margin)
        loss = adversarial + cfg.phi_weight * constraint
        logs = {"loss/generator": adversarial.item(), "loss/phi": constraint.item()}
        if cfg.mask_weight > 0:
            contrast = mask_contrast_loss(fake, reference, masks, cfg.mask_keep, cfg.mask_ring, cfg.mask_highlight,
                                          cfg.mask_rise)
            loss = loss + cfg.mask_weight * contrast
            logs["loss/mask"] = contrast.item()
        if cfg.shadow_weight > 0:
            shape = shadow_shape_loss(fake, reference, masks, cfg.mask_ring)
            loss = loss + cfg.shadow_weight * shape
            logs["loss/shadow_shape"] = shape.item()
        if cfg.generator.donor_levels:
            # the net's own levels, which the donor's replace, held at the render's: nothing else
            # holds them. A plain straight-through gradient drives them to ±1 (ties: one flat gray
            # chip after the matching), this anchor or not; `_RanksOnly` removes that push, and
            # this keeps slower drifts in check. The net keeps choosing the ranks
            anchor = (gray_levels(drawn.own_levels) - gray_levels(render)).abs().mean()
            loss = loss + DONOR_ANCHOR * anchor
            logs["loss/anchor"] = anchor.item()
        if cfg.levels_weight > 0:
            # of the whole image, through the tone curve alone: asked of all of the generator, the
            # smooth correction meets it by painting bright bands beside the shadows (docs/gan.md)
            levels = energy_distance(gray_levels(drawn.curve_only), real_levels)
            loss = loss + cfg.levels_weight * levels
            logs["loss/levels"] = levels.item()
        opt_g.zero_grad(set_to_none=True)
        loss.backward()
        logs["grad_norm/generator"] = grad_norm(generator)
        opt_g.step()
        if average is not None:
            average.update_parameters(generator)
        return logs

    state = {"generator": generator, "critic": critic, "opt_g": opt_g, "opt_c": opt_c,
             "real": real_batches, "renders": render_batches, "noise": noise, "view_noise": view_noise}
    if generator.style_size:
        state["style_noise"] = style_noise
    if average is not None:
        state["generator_ema"] = average
    return Phases(state=state,
                  inputs={"real": (str(inputs["real"]), real.fingerprint()),
                          "renders": (str(inputs["renders"]), renders.fingerprint()),
                          "phi": (str(inputs["phi"]), file_fingerprint(Path(encoder.checkpoint)))},
                  generator_step=generator_step,
                  samples=lambda: before_after(average.module if average is not None else generator, fixed,
                                               fixed_code),
                  score="loss/wasserstein", critic_step=critic_step, critic_steps=cfg.n_critic)


SASGAN = Kind("sasgan", SasganRun, build)
