"""The DCGAN baseline run: z → image with the same WGAN-GP critic as the SAS GAN."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from sasmi.gan.critic import Critic
from sasmi.gan.data import Batches, ImageSet
from sasmi.gan.dcgan import DCGANConfig, DCGANGenerator, sample
from sasmi.gan.distributed import parallel, world
from sasmi.gan.kinds.common import GanRun, Noise, adam, adversarial_loss, critic_phase, critic_view, grad_norm
from sasmi.gan.loop import Kind, Logs, Phases
from sasmi.gan.run import check_number
from sasmi.errors import SasmiError
from sasmi.images import write_gray


@dataclass(frozen=True)
class DcganRun(GanRun):
    dcgan: DCGANConfig = DCGANConfig()
    final_samples: int = 256  # images written to final_samples/ when the run completes

    def validate(self) -> "DcganRun":
        super().validate()
        check_number("final_samples", self.final_samples)
        if self.critic.phi_features:
            raise SasmiError("critic.phi_features: the DCGAN baseline has no φ; it is the SAS GAN's option")
        return self


def build(cfg: DcganRun, inputs: dict[str, Path], device: torch.device) -> Phases:
    # ---- data and the run's noise stream
    real = ImageSet(inputs["real"], cfg.size)
    real_batches = Batches(real, cfg.batch, seed=cfg.seed)
    noise, view_noise = Noise(cfg.seed + 2), Noise(cfg.seed + 4)
    fixed_z = torch.randn(16, cfg.dcgan.z_dim, generator=torch.Generator().manual_seed(cfg.seed + 3)).to(device)

    # ---- models and optimisers
    generator = DCGANGenerator(cfg.dcgan, cfg.size).to(device)
    critic = Critic(cfg.critic, cfg.size).to(device)
    opt_g = adam(generator.parameters(), cfg.lr, cfg)
    opt_c = adam(critic.parameters(), cfg.critic_lr or cfg.lr, cfg)
    view = critic_view(cfg, view_noise)  # real and fake alike
    train_generator, train_critic = parallel(generator), parallel(critic)  # as in the SAS GAN (sasgan.py)

    def codes() -> torch.Tensor:
        return noise.normal(cfg.batch // world().size, cfg.dcgan.z_dim).to(device)  # (B, z_dim) standard normal

    critic_step = critic_phase(cfg, train_critic, opt_c, lambda: real_batches.next().to(device),
                               lambda: generator(codes()), view, noise, device)

    def generator_step() -> Logs:
        """Fool the critic."""
        adversarial = adversarial_loss(cfg, critic(view(train_generator(codes()))))
        opt_g.zero_grad(set_to_none=True)
        adversarial.backward()
        norm = grad_norm(generator)
        opt_g.step()
        return {"loss/generator": adversarial.item(), "grad_norm/generator": norm}

    @torch.no_grad()
    def samples() -> list[torch.Tensor]:
        generator.eval()
        rows = list(generator(fixed_z).split(8))
        generator.train()
        return rows

    def finish(out: Path) -> None:
        for i, image in enumerate(sample(generator, cfg.final_samples, seed=cfg.seed)):
            write_gray(out / "final_samples" / f"{i:06d}.png", image)
        generator.train()

    return Phases(state={"generator": generator, "critic": critic, "opt_g": opt_g, "opt_c": opt_c,
                         "real": real_batches, "noise": noise, "view_noise": view_noise},
                  inputs={"real": (str(inputs["real"]), real.fingerprint())},
                  generator_step=generator_step, samples=samples, score="loss/wasserstein",
                  critic_step=critic_step, critic_steps=cfg.n_critic, finish=finish)


DCGAN = Kind("dcgan", DcganRun, build)
