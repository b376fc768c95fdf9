"""`sasmi train {autoencoder,sasgan,dcgan}`: the φ autoencoder, the SAS GAN, the DCGAN baseline.

Flags left out take the defaults of the run configs in gan/kinds/ (docs/gan.md), or for
`sasgan --recipe NAME|FILE` the recipe's settings, which flags given beside it override: the
recipe `sasmi fit --recipe NAME` trains, step for step. A run's
resolved settings travel inside each checkpoint (and RUN/config.json). With --resume only
--steps may change; --steps is the total to reach. Under `torchrun --nproc_per_node N -m sasmi
train ...` the N processes share --batch and train one run (gan/distributed.py).
"""
from __future__ import annotations

import argparse
import functools
from dataclasses import replace

from sasmi.cli.common import add_device, add_threads, apply_threads, resolve_device

NETS = ("small", "paper")
TRAINING_FLAGS = ("steps", "size", "batch", "lr", "seed", "betas", "checkpoint_every", "n_critic", "critic_lr",
                  "regulariser", "gp_weight", "r1_gamma", "phi_weight", "phi_margin", "ema", "mask_weight", "mask_keep")


def _kind(name: str):
    """The CLI edge: the one place a run kind is chosen by its name."""
    from sasmi.gan.kinds.autoencoder import AUTOENCODER
    from sasmi.gan.kinds.dcgan import DCGAN
    from sasmi.gan.kinds.sasgan import SASGAN

    return {"autoencoder": AUTOENCODER, "sasgan": SASGAN, "dcgan": DCGAN}[name]


class _DefaultsHelp(argparse.HelpFormatter):
    """Shows each flag's default from the kind's config dataclass, read only when --help
    is asked for, so that building the parser does not import torch."""

    def __init__(self, prog: str, kind: str):
        super().__init__(prog)
        self.kind = kind

    def _get_help_string(self, action: argparse.Action) -> str:
        defaults = _kind(self.kind).config()
        if hasattr(defaults, action.dest) and action.dest not in ("critic", "generator", "dcgan", "augment"):
            return f"{action.help} (default: {getattr(defaults, action.dest)})"
        return action.help


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--real", required=True, metavar="DIR", help="real images, searched recursively")
    p.add_argument("--out", required=True, metavar="RUN", help="run folder to create (or to continue with --resume)")
    p.add_argument("--steps", type=int, help="total updates to reach")
    p.add_argument("--size", type=int, help="image size S, a multiple of 16")
    p.add_argument("--batch", type=int, help="batch size")
    p.add_argument("--lr", type=float, help="Adam learning rate")
    p.add_argument("--betas", type=float, nargs=2, metavar=("B1", "B2"), help="Adam betas")
    p.add_argument("--seed", type=int, help="seed of weights, data order, augmentation and noise")
    p.add_argument("--checkpoint-every", type=int, metavar="N",
                   help="steps between checkpoints; also best.pt's interval")
    p.add_argument("--resume", action="store_true", help="continue RUN from checkpoints/last.pt")
    add_device(p)
    add_threads(p)


def _add_gan(p: argparse.ArgumentParser) -> None:
    p.add_argument("--n-critic", type=int, help="critic updates per generator update")
    p.add_argument("--critic-lr", type=float, help="the critic's Adam rate (None: --lr)")
    p.add_argument("--regulariser", choices=("gp", "r1"),
                   help="gp: Wasserstein loss + gradient penalty; r1: logistic loss + R1 on reals (StyleGAN2)")
    p.add_argument("--gp-weight", type=float, help="λ of the gradient penalty")
    p.add_argument("--r1-gamma", type=float, help="γ of R1")
    p.add_argument("--augment", action="store_true",
                   help="show the critic real and fake through the same differentiable augmentation (translation, "
                        "cutout, brightness/contrast, up-down flip; never left-right) (default: off)")
    p.add_argument("--patch-critic", action="store_true",
                   help="the critic scores every 46-px patch with shared weights and averages them (PatchGAN) instead "
                        "of one linear unit over the whole chip (default: off)")
    p.add_argument("--net", choices=NETS, help="network sizes: small (CPU) or paper (256², GPU) (default: small)")


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("train", help="train the φ autoencoder, the SAS GAN or the DCGAN baseline",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    kinds = parser.add_subparsers(dest="kind", required=True, metavar="KIND")

    def add_kind(name: str, help: str) -> argparse.ArgumentParser:
        return kinds.add_parser(name, help=help, formatter_class=functools.partial(_DefaultsHelp, kind=name))

    p = add_kind("autoencoder", "φ: L2 autoencoder on real chips")
    _add_common(p)

    p = add_kind("sasgan", "render → real: WGAN-GP + φ constraint")
    _add_common(p)
    p.add_argument("--renders", required=True, metavar="DIR", help="a render set (or a folder of renders)")
    p.add_argument("--phi", required=True, metavar="RUN_AE", help="a trained autoencoder run")
    p.add_argument("--recipe", metavar="NAME|FILE",
                   help="start from a recipe's settings (gan/recipes: real_levels, the default of `sasmi fit`; "
                        "small_data; baseline) or a TOML file of them; the flags below override its keys "
                        "(default: none, the settings shown)")
    _add_gan(p)
    p.add_argument("--phi-weight", type=float, help="weight of the φ loss")
    p.add_argument("--phi-margin", type=float, help="γ: free relative φ change")
    p.add_argument("--ema", type=float, help="decay of the generator moving average that translates; 0: none")
    p.add_argument("--mask-weight", type=float,
                   help="weight of the mask contrast term (keeps shadows dark, highlights bright; needs masks/)")
    p.add_argument("--mask-keep", type=float, help="fraction of a render's shadow/highlight contrast to keep")
    p.add_argument("--residual", action="store_true",
                   help="the generator learns a correction to the render, starting from the render itself (default: off)")

    p = add_kind("dcgan", "unconditional baseline: z → image, same objective")
    _add_common(p)
    _add_gan(p)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    apply_threads(args.threads)  # before torch is imported
    from sasmi.gan import distributed
    from sasmi.gan.critic import CRITIC_NETS, CriticConfig
    from sasmi.gan.dcgan import DCGAN_NETS
    from sasmi.gan.generator import GENERATOR_NETS, GeneratorConfig
    from sasmi.gan.kinds.sasgan import SASGAN
    from sasmi.gan.loop import resolve_config, train

    kind = _kind(args.kind)
    inputs = {"real": args.real} | ({"renders": args.renders, "phi": args.phi} if kind is SASGAN else {})
    recipe = {}
    if getattr(args, "recipe", None):
        from sasmi.gan.recipes import load_recipe

        recipe = load_recipe(args.recipe)
    overrides = recipe | {k: getattr(args, k) for k in TRAINING_FLAGS if getattr(args, k, None) is not None}
    if "betas" in overrides:
        overrides["betas"] = tuple(overrides["betas"])
    if getattr(args, "augment", False):
        from sasmi.gan.augment import AugmentConfig

        overrides["augment"] = AugmentConfig.recommended()
    if getattr(args, "net", None):
        overrides["critic"] = CRITIC_NETS[args.net]
        overrides |= {"generator": GENERATOR_NETS[args.net]} if kind is SASGAN else {"dcgan": DCGAN_NETS[args.net]}
    if getattr(args, "patch_critic", False):
        overrides["critic"] = replace(overrides.get("critic", CriticConfig()), patch=True)
    if getattr(args, "residual", False):
        overrides["generator"] = replace(overrides.get("generator", GeneratorConfig()), residual=True)
    device = distributed.start(resolve_device(args.device))
    main = distributed.world().main
    try:
        cfg = resolve_config(kind, args.out, overrides, args.resume)
        distributed.barrier()  # every process has looked at --out before the main one writes into it
        done = train(kind, cfg, args.out, inputs, device, args.resume)
        distributed.barrier()  # leave together: a process gone while the main one writes can abort the group
    finally:
        distributed.stop()
    if not main:
        return 0
    if done.step == done.start and args.resume:
        print(f"sasmi train {args.kind}: {done.out} is already at step {done.step} (--steps {cfg.steps}); "
              f"nothing trained; raise --steps to train on")
    else:
        print(f"sasmi train {args.kind}: {done.out} trained steps {done.start + 1}-{done.step}")
    return 0
