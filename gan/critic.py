"""The critic shared by the SAS GAN and the DCGAN baseline (a DCGAN discriminator), and the
SAS GAN's alternative that judges φ's feature maps instead of pixels (`PhiCritic`).

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
    # judge the frozen φ encoder's four feature maps instead of the pixels (Projected GAN, Sauer et
    # al. 2021): φ learnt what real chips look like from every real chip, seafloor included, so the
    # critic's ~100 target chips train small heads on top of it, not a whole net (SAS GAN only)
    phi_features: bool = False
    # judge each chip standardised (its pixels' mean 0, standard deviation 1): its overall level and
    # contrast are left to the gray-level term. Learning from ~100 chips, the critic pulls the
    # levels away from real while the term pulls them back, through the same curve (docs/gan.md)
    standardise: bool = False


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
        self.size, self.standardise = size, cfg.standardise

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (B, 1, S, S) in [-1, 1] → (B,) unbounded scores
        assert x.shape[1:] == (1, self.size, self.size), x.shape
        if self.standardise:  # (B, 1, S, S), each chip mean 0, std 1 (the floor: a flat chip stays finite)
            x = (x - x.mean(dim=(1, 2, 3), keepdim=True)) / x.std(dim=(1, 2, 3), keepdim=True).clamp_min(1e-3)
        features = self.features(x)  # (B, 8w, S/16, S/16)
        if self.patch:
            return self.score(features).mean(dim=(1, 2, 3))
        return self.score(features.flatten(1))[:, 0]


class PhiCritic(nn.Module):
    """Heads on the frozen φ encoder's feature maps, their scores summed: (B, 1, S, S) → (B,).

    Each map (c, r, r) goes down by 4×4 stride-2 convs with LeakyReLU(0.2) to 4 × 4, then one
    linear unit: every head sees the whole chip at its own scale (S/2 speckle up to S/16 shapes).
    The encoder is held outside the module's parameters: the critic's optimiser and
    `requires_grad_` never reach it, and φ stays the one the φ constraint and the evaluation use.
    Gradients still flow through it to the input, for the penalty and the generator.
    """

    def __init__(self, cfg: CriticConfig, size: int, encoder: nn.Module):
        super().__init__()
        assert size % 16 == 0 and not cfg.patch, (size, cfg)
        self.encoder = [encoder]  # a list: not a submodule (see above)
        with torch.no_grad():
            shapes = [m.shape[1:3] for m in encoder.feature_maps(torch.zeros(1, 1, size, size,
                                                                        device=next(encoder.parameters()).device))]
        w = 2 * cfg.width
        self.heads = nn.ModuleList()
        for channels, side in shapes:
            layers, c_in = [], channels
            while side > 4:
                layers += [nn.Conv2d(c_in, w, 4, stride=2, padding=1), nn.LeakyReLU(0.2)]
                c_in, side = w, side // 2
            self.heads.append(nn.Sequential(*layers, nn.Flatten(), nn.Linear(c_in * side * side, 1)))
        self.size = size

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (B, 1, S, S) in [-1, 1] → (B,) unbounded scores
        assert x.shape[1:] == (1, self.size, self.size), x.shape
        maps = self.encoder[0].feature_maps(x)  # 4 × (B, c, r, r), r = S/2 … S/16
        return sum(head(m)[:, 0] for head, m in zip(self.heads, maps))


def make_critic(cfg: CriticConfig, size: int, encoder: nn.Module | None = None) -> nn.Module:
    """The critic `cfg` asks for; `encoder` (the frozen φ) is needed by `phi_features` only."""
    if cfg.phi_features:
        assert encoder is not None, "phi_features needs the φ encoder"
        return PhiCritic(cfg, size, encoder)
    return Critic(cfg, size)
