"""`sasmi fit --real DIR --out RUN`: real chips -> φ, renders, SAS GAN, translations, realism report."""
from __future__ import annotations

import argparse

from sasmi.cli.common import add_device, add_threads, apply_threads, resolve_device

MIN_COUNT = 8


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fit", help="one command from real chips to a trained SAS GAN and its realism report",
                       description="Trains φ into RUN/phi, renders the preset into RUN/renders, lays their targets on real "
                                   "seafloor chips into RUN/on_floors (see --floors), trains the SAS GAN "
                                   "into RUN/sasgan within the time budget, translates into RUN/translated and "
                                   "writes RUN/report/ (sasmi evaluate's metrics.json). Rerun to resume; raise "
                                   "--minutes to train on.")
    p.add_argument("--real", required=True, metavar="DIR", help="real target chips the SAS GAN learns from")
    p.add_argument("--out", required=True, metavar="RUN", help="run folder")
    p.add_argument("--phi-real", metavar="DIR", help="chips φ learns from (default: --real); targets and seafloor")
    p.add_argument("--validation", metavar="DIR",
                   help="real chips the report compares with (default: validation/CATEGORY beside a --real of "
                        "`sasmi split`'s train/CATEGORY, else --real itself, which flatters)")
    p.add_argument("--minutes", type=float, default=60.0, help="time budget of the whole run")
    p.add_argument("--size", type=int, default=128, help="image size, a multiple of 16")
    p.add_argument("--preset", default="cylinder_chip", help="scene preset: a TOML file or a shipped preset's name")
    p.add_argument("--count", type=int, default=400, help="chips rendered for the GAN and the report")
    p.add_argument("--seed", type=int, default=0, help="seed of the renders and of every training")
    p.add_argument("--recipe", default="real_levels", metavar="NAME|FILE",
                   help="SAS GAN settings: a shipped recipe (real_levels; small_data, the same without a real chip's "
                        "gray levels after translation; baseline) or a TOML file of them, as `sasmi train sasgan --recipe`")
    p.add_argument("--phi", metavar="RUN", default="",
                   help="an autoencoder run to use instead of training one (e.g. one φ for several recipes)")
    floors = p.add_mutually_exclusive_group()
    floors.add_argument("--floors", metavar="DIR",
                        help="real seafloor chips (of the same sonar as --real; chips unlike its floors are passed "
                             "over): the renders' targets and shadows are laid on them (RUN/on_floors) before the "
                             "GAN (docs/gan.md, *Real floors*). Default: --phi-real's seafloor/ folder, if it has one")
    floors.add_argument("--no-floors", dest="floors", action="store_const", const="",
                        help="keep the renders' own floors")
    add_device(p)
    add_threads(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.errors import SasmiError
    from sasmi.realism.fit import FitPlan, fit, with_defaults

    if args.count < MIN_COUNT:
        raise SasmiError(f"--count {args.count}: is below {MIN_COUNT} (the report's precision and recall compare "
                         f"nearest neighbours among {MIN_COUNT} or more chips)")
    apply_threads(args.threads)  # before torch is imported
    plan = with_defaults(FitPlan(real=args.real, out=args.out, phi_real=args.phi_real, validation=args.validation,
                                 minutes=args.minutes, size=args.size, preset=args.preset, count=args.count,
                                 seed=args.seed, recipe=args.recipe, phi=args.phi, floors=args.floors))
    path = fit(plan, resolve_device(args.device))
    print(path)
    return 0
