"""The SAS GAN run: render → realistic image, WGAN-GP critic + the φ constraint (Reed et al.)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from gan.autoencoder import load_encoder
from gan.critic import Critic
from gan.data import Batches, ImageSet
from gan.generator import Generator, GeneratorConfig
from gan.kinds.common import GanRun, Noise, before_after, critic_phase, grad_norm, spread
from gan.loop import Kind, Logs, Phases
from gan.losses import generator_loss, phi_loss
from gan.run import check_number, file_fingerprint
from sasmi.errors import SasmiError


@dataclass(frozen=True)
class SasganRun(GanRun):
    generator: GeneratorConfig = GeneratorConfig()
    phi_weight: float = 100.0  # at 10 the adversarial term wins and content is lost (docs/gan.md)
    phi_margin: float = 0.25  # γ: φ(G(render)) may move this fraction of ‖φ(render)‖ for free (docs/gan.md)

    def validate(self) -> "SasganRun":
        super().validate()
        check_number("--phi-weight", self.phi_weight, 0.0, 1e6)
        check_number("--phi-margin", self.phi_margin, 0.0, 10.0, why="a fraction of ‖φ(render)‖")
        return self


def build(cfg: SasganRun, inputs: dict[str, Path], device: torch.device) -> Phases:
    # ---- data and the frozen φ encoder
    real, renders = ImageSet(inputs["real"], cfg.size), ImageSet(inputs["renders"], cfg.size)
    real_batches = Batches(real, cfg.batch, seed=cfg.seed)
    render_batches = Batches(renders, cfg.batch, seed=cfg.seed + 1)
    noise = Noise(cfg.seed + 2)
    fixed = renders.center(spread(len(renders), 8)).to(device)  # (n, 1, S, S) in [-1, 1]
    encoder = load_encoder(inputs["phi"], device)  # (B, 1, S, S) in [-1, 1] → (B, 1024)
    if encoder.image_size != cfg.size:
        raise SasmiError(f"--phi {inputs['phi']}: the autoencoder was trained at {encoder.image_size} px; "
                         f"train the SAS GAN with --size {encoder.image_size} (or retrain it at {cfg.size})")

    # ---- models and optimisers
    generator = Generator(cfg.generator).to(device)
    critic = Critic(cfg.critic, cfg.size).to(device)
    opt_g = torch.optim.Adam(generator.parameters(), lr=cfg.lr, betas=cfg.betas)
    opt_c = torch.optim.Adam(critic.parameters(), lr=cfg.lr, betas=cfg.betas)

    def render_batch() -> torch.Tensor:
        return render_batches.next().to(device)  # (B, 1, S, S) in [-1, 1]

    critic_step = critic_phase(cfg, critic, opt_c, lambda: real_batches.next().to(device),
                               lambda: generator(render_batch()), noise, device)

    def generator_step() -> Logs:
        """Fool the critic while φ(G(render)) stays within γ of φ(render)."""
        render = render_batch()
        fake = generator(render)  # (B, 1, S, S) in [-1, 1]
        adversarial = generator_loss(critic(fake))
        constraint = phi_loss(encoder(render), encoder(fake), cfg.phi_margin)
        opt_g.zero_grad(set_to_none=True)
        (adversarial + cfg.phi_weight * constraint).backward()
        norm = grad_norm(generator)
        opt_g.step()
        return {"loss/generator": adversarial.item(), "loss/phi": constraint.item(), "grad_norm/generator": norm}

    phi_ckpt = Path(encoder.checkpoint)
    return Phases(state={"generator": generator, "critic": critic, "opt_g": opt_g, "opt_c": opt_c,
                         "real": real_batches, "renders": render_batches, "noise": noise},
                  inputs={"real": (str(inputs["real"]), real.fingerprint()),
                          "renders": (str(inputs["renders"]), renders.fingerprint()),
                          "phi": (str(inputs["phi"]), file_fingerprint(phi_ckpt))},
                  generator_step=generator_step, samples=lambda: before_after(generator, fixed),
                  score="loss/wasserstein", critic_step=critic_step, critic_steps=cfg.n_critic)


SASGAN = Kind("sasgan", SasganRun, build)
