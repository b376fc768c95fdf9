"""The φ autoencoder run: L2 reconstruction of real chips."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from sasmi.gan.autoencoder import Autoencoder, AutoencoderConfig
from sasmi.gan.data import Batches, ImageSet
from sasmi.gan.distributed import parallel
from sasmi.gan.kinds.common import before_after, grad_norm, spread
from sasmi.gan.loop import Kind, Logs, Phases
from sasmi.gan.losses import reconstruction_loss
from sasmi.gan.run import RunConfig


@dataclass(frozen=True)
class AutoencoderRun(RunConfig):
    steps: int = 2000  # the reconstruction loss flattens out by then at 128²
    batch: int = 8  # reconstruction is cheap; a larger batch steadies the L2 gradient
    autoencoder: AutoencoderConfig = AutoencoderConfig()


def build(cfg: AutoencoderRun, inputs: dict[str, Path], device: torch.device) -> Phases:
    real = ImageSet(inputs["real"], cfg.size)
    batches = Batches(real, cfg.batch, seed=cfg.seed)
    fixed = real.center(spread(len(real), 8)).to(device)  # (n, 1, S, S) in [-1, 1]
    model = Autoencoder(cfg.autoencoder).to(device)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=cfg.betas)
    train_model = parallel(model)  # gradients averaged across processes (gan/distributed.py)

    def generator_step() -> Logs:
        x = batches.next().to(device)  # (B, 1, S, S) in [-1, 1]
        loss = reconstruction_loss(train_model(x), x)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        norm = grad_norm(model)
        opt.step()
        return {"loss/reconstruction": loss.item(), "grad_norm/autoencoder": norm}

    return Phases(state={"autoencoder": model, "opt": opt, "real": batches},
                  inputs={"real": (str(inputs["real"]), real.fingerprint())},
                  generator_step=generator_step, samples=lambda: before_after(model, fixed),
                  score="loss/reconstruction")


AUTOENCODER = Kind("autoencoder", AutoencoderRun, build)
