"""The autoencoder whose encoder gives φ, the 1024-dim image descriptor.

φ serves twice: the SAS GAN keeps φ(G(render)) near φ(render) so the generator changes
texture, not content, and the evaluation compares φ statistics of real and generated
sets (a φ-FID). It is trained with L2 reconstruction on real chips only.

Encoder: four [3×3 conv → ReLU → 2×2 max-pool] stages, S → S/16, the last with 16
channels; the (16, S/16, S/16) map is average-pooled to a fixed 8×8 grid and flattened:
16·8·8 = 1024 at every size. At 128² (the chip size) the pooling is the identity, so φ
is exactly the flattened last stage as in Reed et al.; at 256² each φ entry averages a
2×2 cell; below 128² cells are repeated (φ then has fewer than 1024 distinct entries,
acceptable for tests, not for evaluation). A final linear layer was the alternative; it
adds S²-dependent weights and a dense bottleneck that pooling does not need.
Decoder: the 8×8 grid back to S/16, then four [nearest ×2 → 3×3 conv] stages, ReLU
between them and tanh at the end, so reconstructions live in [-1, 1] like the input.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.nn as nn
import torch.nn.functional as F

from sasmi.gan.run import config_from_dict, load_weights, read_run

PHI_DIM = 1024
PHI_GRID = 8  # PHI_DIM == widths[-1] * PHI_GRID**2


@dataclass(frozen=True)
class AutoencoderConfig:
    widths: tuple[int, ...] = (32, 64, 128, 16)  # channels of the four encoder stages; the last times 8² is φ's 1024

    def __post_init__(self):
        if len(self.widths) != 4 or self.widths[-1] * PHI_GRID ** 2 != PHI_DIM:
            raise ValueError(f"widths must be four stages ending in {PHI_DIM // PHI_GRID ** 2} channels, "
                             f"got {self.widths}")


class Encoder(nn.Module):
    def __init__(self, cfg: AutoencoderConfig):
        super().__init__()
        layers, c_in = [], 1
        for c_out in cfg.widths:
            layers += [nn.Conv2d(c_in, c_out, 3, padding=1), nn.ReLU(), nn.MaxPool2d(2)]
            c_in = c_out
        self.stages = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # x: (B, 1, S, S) in [-1, 1] → φ: (B, 1024), non-negative
        assert x.ndim == 4 and x.shape[1] == 1 and x.shape[-1] % 16 == 0, x.shape
        h = F.adaptive_avg_pool2d(self.stages(x), PHI_GRID)
        return h.flatten(1)

    def feature_maps(self, x: torch.Tensor) -> list[torch.Tensor]:
        """Each stage's output: (B, widths[i], S/2^(i+1), S/2^(i+1)), non-negative; x as in forward."""
        maps = []
        for i in range(0, len(self.stages), 3):  # [conv, ReLU, pool] per stage
            x = self.stages[i + 2](self.stages[i + 1](self.stages[i](x)))
            maps.append(x)
        return maps


class Decoder(nn.Module):
    def __init__(self, cfg: AutoencoderConfig):
        super().__init__()
        self.c0 = cfg.widths[-1]
        channels = list(reversed(cfg.widths[:-1])) + [1]  # e.g. 128, 64, 32, 1
        layers, c_in = [], self.c0
        for i, c_out in enumerate(channels):
            layers += [nn.Upsample(scale_factor=2, mode="nearest"), nn.Conv2d(c_in, c_out, 3, padding=1)]
            layers.append(nn.ReLU() if i < len(channels) - 1 else nn.Tanh())
            c_in = c_out
        self.stages = nn.Sequential(*layers)

    def forward(self, phi: torch.Tensor, size: int) -> torch.Tensor:
        # phi: (B, 1024) → (B, 1, size, size) in [-1, 1]
        h = phi.view(-1, self.c0, PHI_GRID, PHI_GRID)
        h = F.interpolate(h, size=size // 16, mode="nearest")
        return self.stages(h)


class Autoencoder(nn.Module):
    def __init__(self, cfg: AutoencoderConfig):
        super().__init__()
        self.encoder = Encoder(cfg)
        self.decoder = Decoder(cfg)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # (B, 1, S, S) in [-1, 1] → reconstruction, same shape and range
        return self.decoder(self.encoder(x), x.shape[-1])


def load_encoder(run_dir: str | os.PathLike, device: str | torch.device = "cpu",
                 checkpoint: str = "best") -> Encoder:
    """The frozen φ encoder of an autoencoder run: (B, 1, S, S) in [-1, 1] → (B, 1024).

    `.image_size` is the size it was trained at, `.checkpoint` the file it came from;
    eval mode, no gradients to its weights.
    """
    saved = read_run(run_dir, "autoencoder", checkpoint)
    model = Autoencoder(config_from_dict(AutoencoderConfig, saved.config.get("autoencoder", {}), str(saved.path)))
    load_weights(model, saved, "autoencoder")
    encoder = model.encoder.to(device).eval().requires_grad_(False)
    encoder.image_size, encoder.checkpoint = saved.config["size"], saved.path
    return encoder
