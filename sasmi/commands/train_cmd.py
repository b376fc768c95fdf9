"""`sasmi train {autoencoder,sasgan,dcgan}`: the φ autoencoder, the SAS GAN, the DCGAN baseline.

Flags left out take the defaults of gan/train.py (documented in docs/gan.md); a run's
resolved settings are in RUN/config.json. With --resume only --steps may change.
"""
from __future__ import annotations

import argparse

PRESETS = ("small", "paper")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--real", required=True, metavar="DIR", help="real images, searched recursively")
    p.add_argument("--out", required=True, metavar="RUN", help="run folder to create (or to continue with --resume)")
    p.add_argument("--steps", type=int, help="total generator updates to reach")
    p.add_argument("--size", type=int, help="image size S (multiple of 16)")
    p.add_argument("--batch", type=int, help="batch size")
    p.add_argument("--lr", type=float, help="Adam learning rate")
    p.add_argument("--seed", type=int, help="seed of weights, data order, augmentation and noise")
    p.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda or cuda:N")
    p.add_argument("--resume", action="store_true", help="continue RUN from checkpoints/last.pt")


def _add_gan(p: argparse.ArgumentParser) -> None:
    p.add_argument("--betas", type=float, nargs=2, metavar=("B1", "B2"), help="Adam betas")
    p.add_argument("--n-critic", type=int, help="critic updates per generator update")
    p.add_argument("--preset", choices=PRESETS, help="network sizes: small (CPU) or paper (256², GPU)")


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("train", help="train the φ autoencoder, the SAS GAN or the DCGAN baseline",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    kinds = parser.add_subparsers(dest="kind", required=True, metavar="KIND")

    p = kinds.add_parser("autoencoder", help="φ: L2 autoencoder on real chips")
    _add_common(p)

    p = kinds.add_parser("sasgan", help="render → real: WGAN-GP + φ constraint")
    _add_common(p)
    p.add_argument("--renders", required=True, metavar="DIR", help="a render set (or a folder of renders)")
    p.add_argument("--phi", required=True, metavar="RUN_AE", help="a trained autoencoder run")
    _add_gan(p)
    p.add_argument("--phi-weight", type=float, help="weight of the φ loss")
    p.add_argument("--phi-margin", type=float, help="γ: free relative φ change")

    p = kinds.add_parser("dcgan", help="unconditional baseline: z → image, same objective")
    _add_common(p)
    _add_gan(p)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from gan import train
    from gan.critic import CRITIC_PRESETS
    from gan.dcgan import DCGAN_PRESETS
    from gan.generator import GENERATOR_PRESETS

    overrides = {k: getattr(args, k) for k in ("steps", "size", "batch", "lr", "seed", "betas", "n_critic",
                                               "phi_weight", "phi_margin") if getattr(args, k, None) is not None}
    if "betas" in overrides:
        overrides["betas"] = tuple(overrides["betas"])
    if getattr(args, "preset", None) and args.kind == "sasgan":
        overrides |= {"generator": GENERATOR_PRESETS[args.preset], "critic": CRITIC_PRESETS[args.preset]}
    if getattr(args, "preset", None) and args.kind == "dcgan":
        overrides |= {"dcgan": DCGAN_PRESETS[args.preset], "critic": CRITIC_PRESETS[args.preset]}
    cfg = train.resolve_config(args.kind, args.out, overrides, args.resume)
    device = train.resolve_device(args.device)

    if args.kind == "autoencoder":
        out = train.train_autoencoder(cfg, args.out, args.real, device, args.resume)
    elif args.kind == "sasgan":
        out = train.train_sasgan(cfg, args.out, args.real, args.renders, args.phi, device, args.resume)
    else:
        out = train.train_dcgan(cfg, args.out, args.real, device, args.resume)
    print(f"sasmi train {args.kind}: {out} at step {cfg.steps}")
    return 0
