"""The SAS GAN generator: render → realistic-looking SAS image (Johnson et al. 2016 style).

7×7 conv, two stride-2 convs down, `blocks` residual blocks at 4×width channels, two
[nearest ×2 → 3×3 conv] stages up (transposed convs leave checkerboard patterns that a
critic learns to see), 7×7 conv, tanh. Instance norm, as in CycleGAN's version of the
same net: batches of 4 are too small for batch statistics. It is written as GroupNorm with
one group per channel: the same maths and the same weights (`weight`, `bias` per
channel), and faster than InstanceNorm2d on a CPU. Reflection padding keeps the
borders free of a dark frame. Fully convolutional: any size that is a multiple of 4.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn as nn
import torch.nn.functional as F

from sasmi.gan.run import config_from_dict, load_weights, read_run
from sasmi.gan.upsample import fold_upsampling


@dataclass(frozen=True)
class GeneratorConfig:
    width: int = 16  # channels after the first conv; 2× and 4× after the two downsamplings
    blocks: int = 4  # residual blocks; each adds receptive field at 1/4 resolution
    # learn a correction to the render (in atanh space, its last conv zero-initialised) instead of
    # the whole image: training starts from the render itself, so what the critic asks for is added
    # to a chip that already has the target and its shadow, not redrawn from nothing (docs/gan.md)
    residual: bool = False
    # with `residual`: the correction is averaged over blocks of this many px and upsampled
    # bilinearly, so it changes gray levels, shading and shadows above the speckle's scale and
    # leaves the rendered speckle, whose statistics already match real chips, as it is; 1: per pixel
    correction_scale: int = 1
    # with `residual`: first remap the render's gray levels through a monotone curve chosen per chip
    # from the render's own histogram, its knots at the chip's quantiles, then add the smooth
    # correction. The correction moves local levels but cannot reshape the speckle's distribution
    # (the bright tail, the spread), which a pointwise curve can, without touching where anything is
    tone_curve: bool = False
    # with `tone_curve`: the curve also reads a random code drawn per chip, so one render can take any
    # of many gray-level distributions, as a random real chip's histogram given to each render does
    # (docs/gan.md, *Recipes*); without it the levels are a function
    # of the render's. The gray-level term, an energy distance between sets, rewards the real spread
    tone_style: bool = False
    # the finished chip takes the gray-level distribution of a real chip the GAN learned from, drawn
    # per chip by its code (histogram matching: each pixel keeps its rank). The net then only chooses
    # where things are bright or dark, and the critic, seeing real levels on both sides, judges that
    # arrangement. Random real histograms alone bring renders nearer real chips in φ (docs/results.md)
    donor_levels: bool = False
    # the same match in translation only: the GAN trains as without it (its critic never sees the
    # donors' levels), and each chip it translates then takes one: this beats learning the match
    # (docs/gan.md, *Tried and dropped*)
    donor_levels_after: bool = False
    # with either donor option: pixels darker than this fraction of the chip's median (smoothed over
    # 1 px: a lone dark speckle takes the donor's level) keep their own ratio to the median where
    # that is darker than the donor's level. A donor's darkest levels are its own shadow's, often
    # smaller or paler than the render's: matched alone they pale the shadows (docs/gan.md,
    # *Why each part*); 0: off
    donor_shadow: float = 0.0

    @property
    def takes_donors(self) -> bool:
        """Whether chips take a real chip's levels (learned or after training): the generator keeps donors."""
        return self.donor_levels or self.donor_levels_after


# `small` trains on a CPU at 128²; `paper` is the standard 256² Johnson/CycleGAN size
# (64 wide, 9 blocks); Reed et al.'s exact widths are not known.
RENDER_REACH = 0.98
GENERATOR_NETS = {"small": GeneratorConfig(16, 4), "paper": GeneratorConfig(64, 9)}


def instance_norm(channels: int) -> nn.Module:
    return nn.GroupNorm(channels, channels)


def _conv_norm_relu(c_in: int, c_out: int, kernel: int, stride: int = 1) -> list[nn.Module]:
    return [nn.Conv2d(c_in, c_out, kernel, stride, padding=kernel // 2, padding_mode="reflect"),
            instance_norm(c_out), nn.ReLU()]


class ResidualBlock(nn.Module):
    def __init__(self, c: int):
        super().__init__()
        self.body = nn.Sequential(*_conv_norm_relu(c, c, 3),
                                  nn.Conv2d(c, c, 3, padding=1, padding_mode="reflect"),
                                  instance_norm(c))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


# where the curve's knots sit: at these quantiles of each chip's own gray levels, its darkest and
# brightest pixels included. Half of a SAS chip's pixels lie below −0.68 and nine tenths below
# −0.42 (the median chip): knots every 0.125 over [-1, 1] would leave under three segments to
# shape the first half and five the nine tenths, and eleven for the brightest tenth
TONE_PROBS = torch.cat([torch.tensor([0.0]), torch.linspace(0.02, 0.98, 25), torch.tensor([0.99, 0.995, 1.0])])
TONE_STYLE = 4  # entries of the random code beside them, with `tone_style`
DONOR_PROBS = torch.linspace(0.0, 1.0, 257)  # a real chip's levels, as kept for `donor_levels`


def remap(x: torch.Tensor, levels: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Piecewise-linear map of each image's gray levels taking levels[b] to targets[b]:
    x (B, 1, S, S), levels and targets (B, K) increasing, x within levels' range → like x."""
    flat = x.flatten(1).contiguous()  # (B, S²)
    segment = (torch.searchsorted(levels.contiguous(), flat, right=True) - 1).clamp(0, levels.shape[1] - 2)
    low, high = levels.gather(1, segment), levels.gather(1, segment + 1)
    frac = ((flat - low) / (high - low).clamp_min(1e-6)).clamp(0.0, 1.0)
    out_low, out_high = targets.gather(1, segment), targets.gather(1, segment + 1)
    return (out_low + (out_high - out_low) * frac).view_as(x)


class ToneCurve(nn.Module):
    """A monotone piecewise-linear map of gray levels, one per image: (B, 1, S, S) in [-1, 1] →
    same. Its knots sit at the image's own quantiles (TONE_PROBS), so every segment holds a share
    of the pixels; a small net reads those quantiles and chooses where each knot goes. The gaps
    between the new levels (and from −1 and to 1) are a softmax, so the map is increasing and
    stays in [-1, 1]; they start as the image's own gaps (last layer zero), so it starts as the
    identity. With `style` entries, a code (B, style) ~ N(0, 1) is read beside the quantiles."""

    def __init__(self, hidden: int = 32, style: int = 0):
        super().__init__()
        self.style = style
        self.choose = nn.Sequential(nn.Linear(len(TONE_PROBS) + style, hidden), nn.ReLU(),
                                    nn.Linear(hidden, len(TONE_PROBS) + 1))
        nn.init.zeros_(self.choose[-1].weight)
        nn.init.zeros_(self.choose[-1].bias)

    def knots(self, x: torch.Tensor, code: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The image's quantiles and the levels they go to: (B, K), (B, K), K = len(TONE_PROBS)."""
        levels = torch.quantile(x.flatten(1), TONE_PROBS.to(x), dim=1).T.contiguous()  # (B, K) in [-1, 1]
        edges = torch.cat([-torch.ones_like(levels[:, :1]), levels, torch.ones_like(levels[:, :1])], dim=1)
        gaps = edges.diff(dim=1).clamp_min(1e-6)  # (B, K + 1), sum ≈ 2; a floor: the log of a tie stays finite
        seen = levels
        if self.style:
            code = torch.randn(len(x), self.style, device=x.device, dtype=x.dtype) if code is None else code
            assert code.shape == (len(x), self.style), code.shape
            seen = torch.cat([levels, code.to(x)], dim=1)  # (B, K + style)
        new_gaps = 2.0 * torch.softmax(gaps.log() + self.choose(seen), dim=1)  # (B, K + 1), sums to 2
        return levels, (new_gaps.cumsum(dim=1)[:, :-1] - 1.0).clamp(-1.0, 1.0)  # clamp: rounding only

    def forward(self, x: torch.Tensor, code: torch.Tensor | None = None) -> torch.Tensor:
        return remap(x, *self.knots(x, code))  # the knots are x's own quantiles: x lies within them


def donor_quantiles(x: torch.Tensor) -> torch.Tensor:
    """Each image's gray levels at DONOR_PROBS: (B, 1, S, S) → (B, K)."""
    return torch.quantile(x.flatten(1), DONOR_PROBS.to(x), dim=1).T.contiguous()


def donor_index(code: torch.Tensor, donors: int) -> torch.Tensor:
    """Which of `donors` real chips gives each image its levels: code (B,) ~ N(0, 1) → (B,) int,
    uniform over the donors (the normal's CDF)."""
    uniform = 0.5 * (1.0 + torch.erf(code.double() / 2 ** 0.5))
    return (uniform * donors).long().clamp(0, donors - 1)


_GAUSS_1PX = (lambda g: (g[:, None] * g[None, :] / g.sum() ** 2)[None, None])(
    torch.exp(-torch.arange(-3.0, 4.0) ** 2 / 2))  # (1, 1, 7, 7): σ = 1 px, to 3σ


def keep_shadows(own: torch.Tensor, matched: torch.Tensor, fraction: float) -> torch.Tensor:
    """`matched` where the chip `own` is darker than `fraction` of its median (after a 1-px Gaussian)
    made no brighter than `own`'s ratio to its median times the matched chip's median: each
    (B, 1, S, S) in [-1, 1] → like them. Ratios are of intensities, (x + 1) / 2."""
    u, v = (own + 1) / 2, (matched + 1) / 2  # (B, 1, S, S) in [0, 1]
    smooth = F.conv2d(F.pad(u, (3, 3, 3, 3), mode="reflect"), _GAUSS_1PX.to(u))
    dark = smooth < fraction * smooth.flatten(1).median(dim=1).values.view(-1, 1, 1, 1)
    median_u = u.flatten(1).median(dim=1).values.view(-1, 1, 1, 1).clamp_min(1e-6)
    median_v = v.flatten(1).median(dim=1).values.view(-1, 1, 1, 1)
    kept = torch.where(dark, torch.minimum(v, u / median_u * median_v), v)
    return kept * 2 - 1


class _RanksOnly(torch.autograd.Function):
    """Forward: the chip at a donor's levels. Backward: straight through to the chip at its own
    levels, less what would change its mean or its contrast: those the donor's levels replace, and
    passed on they add up, step after step, until the net's own levels sit at ±1 (ties: one flat
    gray chip after the matching). What is left moves pixels' ranks: which are bright, which dark."""

    @staticmethod
    def forward(ctx, own: torch.Tensor, matched: torch.Tensor) -> torch.Tensor:  # (B, 1, S, S) each
        ctx.save_for_backward(own)
        return matched.clone()

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (own,) = ctx.saved_tensors
        dims = tuple(range(1, own.ndim))
        centred = own - own.mean(dim=dims, keepdim=True)
        grad = grad - grad.mean(dim=dims, keepdim=True)
        spread = (centred * centred).sum(dim=dims, keepdim=True).clamp_min(1e-12)
        return grad - (grad * centred).sum(dim=dims, keepdim=True) / spread * centred, None


class Drawn(NamedTuple):
    """What the generator makes of a batch, each (B, 1, S, S) in [-1, 1]."""
    image: torch.Tensor  # the chip
    curve_only: torch.Tensor  # its values, with the gradient of the tone curve's output alone
    own_levels: torch.Tensor  # the chip at the net's own levels, before a donor's (the chip, without donors)


class Generator(nn.Module):
    def __init__(self, cfg: GeneratorConfig):
        super().__init__()
        w = cfg.width
        self.net = nn.Sequential(
            *_conv_norm_relu(1, w, 7),
            *_conv_norm_relu(w, 2 * w, 3, stride=2),
            *_conv_norm_relu(2 * w, 4 * w, 3, stride=2),
            *[ResidualBlock(4 * w) for _ in range(cfg.blocks)],
            nn.Upsample(scale_factor=2, mode="nearest"), *_conv_norm_relu(4 * w, 2 * w, 3),
            nn.Upsample(scale_factor=2, mode="nearest"), *_conv_norm_relu(2 * w, w, 3),
            nn.Conv2d(w, 1, 7, padding=3, padding_mode="reflect"),
        )
        self.residual, self.correction_scale = cfg.residual, cfg.correction_scale
        self.tone = ToneCurve(style=TONE_STYLE if cfg.tone_style else 0) if cfg.tone_curve else None
        self.donor_levels, self.donor_levels_after = cfg.donor_levels, cfg.donor_levels_after
        self.donor_shadow = cfg.donor_shadow
        donors = cfg.takes_donors
        # (N, len(DONOR_PROBS)): each real chip's levels; filled by `set_donors` when training starts,
        # then kept in the checkpoint with the weights, so translation draws from the same chips
        # (persistent only with donors: a run without them keeps no `donors` entry in its checkpoints)
        self.register_buffer("donors", torch.empty(0, len(DONOR_PROBS)), persistent=donors)
        # entries of `code`: the tone style's, then the donor's; 0: takes none
        self.style_size = (self.tone.style if self.tone is not None else 0) + int(donors)
        if self.residual:
            nn.init.zeros_(self.net[-1].weight)
            nn.init.zeros_(self.net[-1].bias)

    def set_donors(self, real: torch.Tensor) -> None:
        """Keep the gray levels of real chips (N, 1, S, S) in [-1, 1] for `donor_levels`."""
        self.donors = donor_quantiles(real.float()).to(self.donors)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        saved = state_dict.get(prefix + "donors")
        if saved is not None:  # the number of donor chips is the run's, not the config's
            self.donors = torch.empty_like(saved, device=self.donors.device)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def forward(self, render: torch.Tensor, code: torch.Tensor | None = None, parts: bool = False):
        # (B, 1, S, S) in [-1, 1] → the chip, (B, 1, S, S) in [-1, 1]; with parts, a Drawn.
        # code: (B, style_size) ~ N(0, 1) for the tone style and the donor; None draws one
        # (translate passes a seeded one)
        assert render.ndim == 4 and render.shape[1] == 1 and render.shape[-1] % 4 == 0, render.shape
        if self.style_size:
            code = torch.randn(len(render), self.style_size, device=render.device) if code is None else code
            assert code.shape == (len(render), self.style_size), code.shape
        if not self.residual:
            image = curve_only = torch.tanh(self.net(render))
        else:
            correction = self.net(render)  # (B, 1, S, S) in atanh units
            if self.correction_scale > 1:
                k = self.correction_scale
                correction = F.interpolate(F.avg_pool2d(correction, k), scale_factor=k, mode="bilinear",
                                           align_corners=False)
            style = None if self.tone is None or not self.tone.style else code[:, :self.tone.style]
            toned = render if self.tone is None else self.tone(render, style)  # (B, 1, S, S) in [-1, 1]
            # 0.98: a black render pixel stays within reach of a gradient (tanh' = 0.04 there, not 0)
            image = torch.tanh(torch.atanh(toned.clamp(-RENDER_REACH, RENDER_REACH)) + correction)
            # the image's values, with the gradient of the curve's output (the correction held as a
            # constant offset, one for one), for the gray-level term: asked of the whole generator,
            # the correction paints bright bands beside the shadows; asked of the curve's output
            # alone, it misses the levels that the correction then moves. Not through the tanh:
            # where the curve reaches ±0.98 its clamp has none
            curve_only = toned + (image - toned).detach()
        own_levels = image
        if self.donor_levels or (self.donor_levels_after and not self.training):
            image = _RanksOnly.apply(image, self.at_donor_levels(image.detach(), code))
        return Drawn(image, curve_only, own_levels) if parts else image

    def at_donor_levels(self, x: torch.Tensor, code: torch.Tensor) -> torch.Tensor:
        """x (B, 1, S, S) in [-1, 1] with the gray levels of the donor that `code` (B, style_size)
        chooses, each pixel keeping its rank; no gradient. The generator's chips with `donor_levels`,
        and the render as the content terms see it: at the same levels as its translation."""
        assert len(self.donors), "donor_levels: set_donors first"
        with torch.no_grad():
            donor = self.donors[donor_index(code[:, -1], len(self.donors))].to(x)  # (B, K)
            own = donor_quantiles(x)  # (B, K)
            matched = remap(x, own, donor)
            return matched if not self.donor_shadow else keep_shadows(x, matched, self.donor_shadow)


def load_generator(run_dir: str | os.PathLike, device: str | torch.device = "cpu",
                   checkpoint: str = "last") -> Generator:
    """The SAS GAN generator of a run (its moving average when the run kept one):
    (B, 1, S, S) in [-1, 1] → same; `.image_size` = S; eval mode."""
    saved = read_run(run_dir, "sasgan", checkpoint)
    generator = Generator(config_from_dict(GeneratorConfig, saved.config.get("generator", {}), str(saved.path)))
    if "generator_ema" in saved.state:  # the moving average translates better than the last weights
        load_weights(generator, saved, "generator_ema", prefix="module.")
    else:
        load_weights(generator, saved, "generator")
    # channels-last convolutions: a 128 px chip in about 17 ms on 2 AVX2 cores, not 24 (outputs within 2e-5)
    generator = generator.to(device, memory_format=torch.channels_last).eval().requires_grad_(False)
    fold_upsampling(generator.net)  # the up stages at the low resolution: same outputs, about 0.85 × the time
    generator.image_size, generator.checkpoint = saved.config["size"], saved.path
    return generator
