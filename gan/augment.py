"""Differentiable augmentation for the critic (Zhao et al. 2020, DiffAugment; Karras et al. 2020, ADA).

With few real images the critic memorises them and its gradients stop teaching the
generator. Showing it real and generated images through the same random, differentiable
transforms keeps it from memorising without teaching the generator the transforms: the
generator's gradient passes through them. The transforms keep SAS physics: no left-right
flip (range runs along x, shadows fall away from the sonar) and no rotation; an up-down
flip (along-track) is fine.

Every draw comes from the run's own resumable torch.Generator, so resume stays exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from sasmi.gan.distributed import draw


@dataclass(frozen=True)
class AugmentConfig:
    """Zeros switch a transform off; `recommended()` is the `--augment` set."""
    translation: float = 0.0  # shift by up to this fraction of S in x and y (reflect-padded)
    cutout: float = 0.0  # blank a square of this fraction of S (DiffAugment: 0.5)
    brightness: float = 0.0  # add U(-b, b) in the signed range
    contrast: float = 0.0  # scale the deviation from the image mean by U(1 - c, 1 + c)
    vflip: bool = False  # flip along-track (image y) with probability 1/2

    @staticmethod
    def recommended() -> "AugmentConfig":
        # DiffAugment's translation and cutout; milder colour (one gray channel, speckle statistics matter)
        return AugmentConfig(translation=0.125, cutout=0.5, brightness=0.25, contrast=0.3, vflip=True)

    @property
    def active(self) -> bool:
        return bool(self.translation or self.cutout or self.brightness or self.contrast or self.vflip)


def augment(x: torch.Tensor, cfg: AugmentConfig, rng: torch.Generator) -> torch.Tensor:
    """(B, 1, S, S) in [-1, 1] → same shape, differentiable in x; each image its own draw."""
    if not cfg.active:
        return x
    b, _, h, w = x.shape

    def uniform(n: int, *shape: int) -> torch.Tensor:
        return draw(rng, n, *shape).to(x.device)  # this process's slice of the global batch's draws

    if cfg.vflip:
        flip = (uniform(b, 1, 1, 1) < 0.5).to(x.dtype)
        x = flip * x.flip(-2) + (1 - flip) * x
    if cfg.brightness:
        x = x + (uniform(b, 1, 1, 1) * 2 - 1) * cfg.brightness
    if cfg.contrast:
        mean = x.mean(dim=(1, 2, 3), keepdim=True)
        x = (x - mean) * (1 + (uniform(b, 1, 1, 1) * 2 - 1) * cfg.contrast) + mean
    if cfg.translation:
        pad = max(1, round(cfg.translation * min(h, w)))
        shifts = (uniform(b, 2) * (2 * pad + 1)).long().clamp_max(2 * pad).tolist()
        padded = F.pad(x, (pad, pad, pad, pad), mode="reflect")
        x = torch.stack([padded[i, :, dy:dy + h, dx:dx + w] for i, (dy, dx) in enumerate(shifts)])
    if cfg.cutout:
        side = max(1, round(cfg.cutout * min(h, w)))
        centre = uniform(b, 2)
        yy = torch.arange(h, device=x.device).view(1, h, 1)
        xx = torch.arange(w, device=x.device).view(1, 1, w)
        top = (centre[:, 0] * (h + 1 - side)).long().view(b, 1, 1)
        left = (centre[:, 1] * (w + 1 - side)).long().view(b, 1, 1)
        inside = (yy >= top) & (yy < top + side) & (xx >= left) & (xx < left + side)
        x = x * (~inside).unsqueeze(1).to(x.dtype)  # blanked to 0: mid-gray in the signed range
    return x
