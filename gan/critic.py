"""The critic shared by the SAS GAN and the DCGAN baseline (a DCGAN discriminator).

Four 4×4 stride-2 convs with LeakyReLU(0.2), S → S/16, then one linear unit (or, with
`patch`, one score per 46-px patch, averaged): an unbounded score, not a probability
(Wasserstein critic). No batch norm: the gradient
penalty constrains the gradient per sample, and batch norm couples the samples of a
batch (Gulrajani et al. 2017, section 4); no other normalisation either, as in their nets.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn as nn


@dataclass(frozen=True)
class CriticConfig:
    width: int = 32  # channels of the first conv, doubled at each of the four stages
    # score each 46-px patch of the S/16 × S/16 feature map with one shared 1×1 conv and average
    # the scores (PatchGAN, Isola et al. 2017), instead of one linear unit over the whole map: the
    # critic judges local texture wherever it is, and every chip is many samples, not one
    patch: bool = False


CRITIC_NETS = {"small": CriticConfig(32), "paper": CriticConfig(64)}


class Critic(nn.Module):
    def __init__(self, cfg: CriticConfig, size: int):
        super().__init__()
        assert size % 16 == 0, size
        w = cfg.width
        layers, c_in = [], 1
        for c_out in (w, 2 * w, 4 * w, 8 * w):
            layers += [nn.Conv2d(c_in, c_out, 4, stride=2, padding=1), nn.LeakyReLU(0.2)]
            c_in = c_out
        self.features = nn.Sequential(*layers)
        self.patch = cfg.patch
        self.score = nn.Conv2d(8 * w, 1, 1) if cfg.patch else nn.Linear(8 * w * (size // 16) ** 2, 1)
        self.size = size

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (B, 1, S, S) in [-1, 1] → (B,) unbounded scores
        assert x.shape[1:] == (1, self.size, self.size), x.shape
        features = self.features(x)  # (B, 8w, S/16, S/16)
        if self.patch:
            return self.score(features).mean(dim=(1, 2, 3))
        return self.score(features.flatten(1))[:, 0]
