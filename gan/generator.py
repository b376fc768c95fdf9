"""The SAS GAN generator: render → realistic-looking SAS image (Johnson et al. 2016 style).

7×7 conv, two stride-2 convs down, `blocks` residual blocks at 4×width channels, two
[nearest ×2 → 3×3 conv] stages up (transposed convs leave checkerboard patterns that a
critic learns to see), 7×7 conv, tanh. Instance norm, as in CycleGAN's version of the
same net: batches of 4 are too small for batch statistics. It is written as GroupNorm with
one group per channel: the same maths and the same weights (`weight`, `bias` per
channel), 2-4× faster than InstanceNorm2d on a CPU (docs/gan.md, Speed). Reflection padding keeps the
borders free of a dark frame. Fully convolutional: any size that is a multiple of 4.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from sasmi.gan.run import config_from_dict, load_weights, read_run


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
    # from the render's own histogram, then add the smooth correction. The correction moves local
    # levels but cannot reshape the speckle's distribution (the bright tail, the spread), which a
    # pointwise curve can, without touching where anything is (docs/gan.md)
    tone_curve: bool = False


# `small` trains on a CPU at 128²; `paper` is the standard 256² Johnson/CycleGAN size
# (64 wide, 9 blocks); Reed et al.'s exact widths were not available to us.
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


TONE_KNOTS = 16  # segments of the tone curve over [-1, 1]
TONE_QUANTILES = torch.linspace(0.01, 0.99, 16)  # what the curve is chosen from: the render's gray levels


class ToneCurve(nn.Module):
    """A monotone piecewise-linear map of [-1, 1] onto itself, one per image, chosen from the
    image's quantiles: (B, 1, S, S) in [-1, 1] → same. The ends stay at ±1; the segments'
    rises are a softmax, so the map is increasing and starts as the identity (last layer zero)."""

    def __init__(self, hidden: int = 32):
        super().__init__()
        self.choose = nn.Sequential(nn.Linear(len(TONE_QUANTILES), hidden), nn.ReLU(), nn.Linear(hidden, TONE_KNOTS))
        nn.init.zeros_(self.choose[-1].weight)
        nn.init.zeros_(self.choose[-1].bias)

    def knots(self, x: torch.Tensor) -> torch.Tensor:
        """(B, K + 1) values of the curve at −1, −1 + 2/K, …, 1."""
        levels = torch.quantile(x.flatten(1), TONE_QUANTILES.to(x), dim=1).T  # (B, 16) in [-1, 1]
        rises = torch.softmax(self.choose(levels), dim=1)  # (B, K), sums to 1
        return torch.cat([torch.full_like(rises[:, :1], -1.0), 2.0 * rises.cumsum(dim=1) - 1.0], dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        knots = self.knots(x)  # (B, K + 1)
        position = (x.clamp(-1.0, 1.0) + 1.0) * (TONE_KNOTS / 2.0)  # (B, 1, S, S) in [0, K]
        segment = position.floor().clamp(max=TONE_KNOTS - 1)
        index = segment.long().flatten(1)  # (B, S²)
        low, high = knots.gather(1, index), knots.gather(1, index + 1)
        frac = (position - segment).flatten(1)
        return (low + (high - low) * frac).view_as(x)


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
        self.tone = ToneCurve() if cfg.tone_curve else None
        if self.residual:
            nn.init.zeros_(self.net[-1].weight)
            nn.init.zeros_(self.net[-1].bias)

    def forward(self, render: torch.Tensor, also_toned: bool = False):
        # (B, 1, S, S) in [-1, 1] → (B, 1, S, S) in [-1, 1]; with also_toned, (that, the render after
        # the tone curve alone): the gray-level term trains the curve, not the spatial correction
        assert render.ndim == 4 and render.shape[1] == 1 and render.shape[-1] % 4 == 0, render.shape
        if not self.residual:
            image = torch.tanh(self.net(render))
            return (image, image) if also_toned else image
        correction = self.net(render)  # (B, 1, S, S) in atanh units
        if self.correction_scale > 1:
            k = self.correction_scale
            correction = F.interpolate(F.avg_pool2d(correction, k), scale_factor=k, mode="bilinear",
                                       align_corners=False)
        toned = render if self.tone is None else self.tone(render)  # (B, 1, S, S) in [-1, 1]
        # 0.98: a black render pixel stays within reach of a gradient (tanh' = 0.04 there, not 0)
        image = torch.tanh(torch.atanh(toned.clamp(-RENDER_REACH, RENDER_REACH)) + correction)
        return (image, toned) if also_toned else image


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
    generator = generator.to(device).eval().requires_grad_(False)
    generator.image_size, generator.checkpoint = saved.config["size"], saved.path
    return generator
