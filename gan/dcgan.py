"""The unconditional baseline: a DCGAN generator z → image (Radford et al. 2016).

A linear layer to (8·width, S/16, S/16), then four 4×4 stride-2 transposed convs with
batch norm and ReLU, tanh at the end: the architecture an "off-the-shelf GAN" means in
Reed et al.'s comparison, so it keeps DCGAN's transposed convs. It is trained with the
same WGAN-GP objective and critic as the SAS GAN, so the comparison isolates the render
input and the φ loss.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn as nn

from sasmi.gan.run import config_from_dict, load_weights, read_run
from sasmi.preprocess import signed_to_unit


@dataclass(frozen=True)
class DCGANConfig:
    z_dim: int = 100  # DCGAN's latent size
    width: int = 32  # channels before the last transposed conv; 8× at the start


DCGAN_NETS = {"small": DCGANConfig(100, 32), "paper": DCGANConfig(100, 64)}


class DCGANGenerator(nn.Module):
    def __init__(self, cfg: DCGANConfig, size: int):
        super().__init__()
        assert size % 16 == 0, size
        w, s0 = cfg.width, size // 16
        self.z_dim, self.c0, self.s0 = cfg.z_dim, 8 * w, s0
        self.project = nn.Linear(cfg.z_dim, 8 * w * s0 * s0, bias=False)
        self.net = nn.Sequential(
            nn.BatchNorm2d(8 * w), nn.ReLU(),
            nn.ConvTranspose2d(8 * w, 4 * w, 4, 2, 1, bias=False), nn.BatchNorm2d(4 * w), nn.ReLU(),
            nn.ConvTranspose2d(4 * w, 2 * w, 4, 2, 1, bias=False), nn.BatchNorm2d(2 * w), nn.ReLU(),
            nn.ConvTranspose2d(2 * w, w, 4, 2, 1, bias=False), nn.BatchNorm2d(w), nn.ReLU(),
            nn.ConvTranspose2d(w, 1, 4, 2, 1), nn.Tanh(),
        )

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        # z: (B, z_dim) standard normal → (B, 1, S, S) in [-1, 1]
        assert z.ndim == 2 and z.shape[1] == self.z_dim, z.shape
        return self.net(self.project(z).view(-1, self.c0, self.s0, self.s0))


@torch.no_grad()
def sample(generator: DCGANGenerator, n: int, seed: int = 0, batch: int = 64) -> np.ndarray:
    """n images from a trained DCGAN generator: (n, S, S) float32 in [0, 1]; the same seed gives the same images."""
    generator.eval()
    device = next(generator.parameters()).device
    z = torch.randn(n, generator.z_dim, generator=torch.Generator().manual_seed(seed))
    out = [generator(z[i:i + batch].to(device)).cpu() for i in range(0, n, batch)]
    return signed_to_unit(torch.cat(out)[:, 0]).numpy()


def load_dcgan(run_dir: str | os.PathLike, device: str | torch.device = "cpu",
               checkpoint: str = "last") -> DCGANGenerator:
    """The DCGAN generator of a run: (B, z_dim) → (B, 1, S, S) in [-1, 1]; `.image_size` = S; eval mode.

    sample(generator, n, seed) turns it into n images in [0, 1].
    """
    saved = read_run(run_dir, "dcgan", checkpoint)
    cfg = config_from_dict(DCGANConfig, saved.config.get("dcgan", {}), str(saved.path))
    generator = DCGANGenerator(cfg, saved.config["size"])
    load_weights(generator, saved, "generator")
    generator = generator.to(device).eval().requires_grad_(False)
    generator.image_size, generator.checkpoint = saved.config["size"], saved.path
    return generator
