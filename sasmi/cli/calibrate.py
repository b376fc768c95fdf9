"""`sasmi calibrate --real DIR [--preset START] [--minutes M] [--params ...] --out RUN`.

Fit a preset's fields (geometry, seafloor, gain, TVG, speckle, noise, target sizes) so that its renders
match a folder of unlabelled real chips as a distribution: the `sasmi stats --check` statistics, each
scaled by its tolerance, and the φ-FID ratio. Writes RUN/preset.toml (loadable by every command),
RUN/report.md, objective.png and sheet.png; rerun the same command to continue. See docs/calibrate.md.
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from sasmi.cli.render import scheduler_address
    from sasmi.realism.calibrate import SAMPLERS, CalibrateConfig
    from sasmi.realism.preset_space import DEFAULT_KNOBS, KNOBS, NAMED_ONLY

    d = CalibrateConfig()
    p = sub.add_parser("calibrate", help="fit a preset to a folder of real chips (derivative-free search)",
                       description=__doc__)
    p.add_argument("--real", type=Path, required=True, metavar="DIR", help="real chips, searched recursively")
    p.add_argument("--preset", type=Path, default=Path("cylinder_chip"), metavar="START",
                   help="preset to start from (default: cylinder_chip)")
    p.add_argument("--out", type=Path, required=True, metavar="RUN", help="run folder; a rerun continues it")
    p.add_argument("--minutes", type=float, default=d.minutes,
                   help=f"search time of all runs together (default: {d.minutes:g})")
    p.add_argument("--trials", type=int, help="or stop after this many trials (default: no limit)")
    p.add_argument("--params", default="default",
                   help=f"comma-separated knobs from: {', '.join(KNOBS)}, and FIELD.spread for the fields "
                        f"outside targets; 'default' is all of those but {', '.join(NAMED_ONLY)}, plus "
                        f"{', '.join(k for k in DEFAULT_KNOBS if k.endswith('.spread'))} "
                        "('default,FIELD.spread' adds one); with [[seafloor]] kinds in the preset, seafloor.FIELD "
                        "sets every kind alike, seafloor[i].FIELD and seafloor[i].weight kind i alone")
    p.add_argument("--chips", type=int, default=d.chips, help=f"renders per trial (default: {d.chips})")
    p.add_argument("--size", type=int, default=d.size, help=f"render and statistics size (default: {d.size})")
    p.add_argument("--spp", type=int, default=d.spp, help=f"samples per pixel (default: {d.spp})")
    p.add_argument("--sampler", choices=SAMPLERS, default=d.sampler, help=f"Optuna sampler (default: {d.sampler})")
    p.add_argument("--step", type=float, default=d.step, metavar="S",
                   help="CMA-ES's first step, a fraction of each knob's range; it grows or shrinks as the search goes "
                        "(default: Optuna's own, 1/6)")
    p.add_argument("--searches", type=int, default=d.searches, metavar="N",
                   help="searches from the start sharing --minutes, each its own sampler path over its own scenes; "
                        "the one whose renders a classifier tells least from the real chips is kept (e.g. --searches 2 "
                        f"--minutes 60; default: {d.searches})")
    p.add_argument("--redraw-scenes", action="store_true",
                   help="each CMA-ES generation renders its own draw of the scenes, all its trials the same one, so "
                        "that the search cannot fit one draw (default: every trial the same scenes; "
                        "docs/calibrate.md)")
    p.add_argument("--workers", type=int, default=1,
                   help="local Dask processes scoring trials side by side (default: 1, here one after another)")
    p.add_argument("--scheduler", type=scheduler_address, metavar="tcp://HOST:PORT",
                   help="score trials on this Dask cluster instead (the run folder needs no shared disk)")
    p.add_argument("--variety-weight", type=float, default=d.variety_weight, metavar="W",
                   help="weight of the real chips no render lies near in φ (recall's shortfall), which keeps the "
                        f"renders as varied as the real chips (default: {d.variety_weight:g}, off; docs/calibrate.md)")
    p.add_argument("--distribution-weight", type=float, default=d.distribution_weight, metavar="W",
                   help="weight of how well each statistic alone (target sizes, gray levels, grain, bands along "
                        "track, ...) tells the renders from the real chips, chip by chip: their distributions, where "
                        f"the tolerances match medians (default: {d.distribution_weight:g}, off; docs/calibrate.md)")
    p.add_argument("--plain-fid", action="store_true",
                   help="score φ by the plain FID ratio, without taking off the small-sample bias by which renders "
                        "less varied than the real chips would score better (docs/calibrate.md)")
    p.add_argument("--phi", type=Path, metavar="RUN", help="φ autoencoder run or weights (default: the shipped φ)")
    p.add_argument("--seed", type=int, default=d.seed, help="preset draws of the trials (default: 0)")
    p.add_argument("--final-chips", type=int, default=d.final_chips, metavar="N",
                   help="renders of the start and of each search's calibrated preset in the report, on scenes no trial "
                        "rendered: the report's figures and the choice between searches are measured on them "
                        f"(default: {d.final_chips})")
    p.add_argument("--contenders", type=int, default=d.contenders, metavar="N",
                   help="best trials on the search's scenes scored again on 4 other draws, the lowest calibrated "
                        f"(default: {d.contenders}; 1: the search's best)")
    p.add_argument("--profile-trials", type=int, default=d.profile_trials, metavar="N",
                   help="settings tried a side of each knob the search's trials leave pinned or undecided, the knob "
                        "held 15 %% away and the others searched again "
                        f"(default: {d.profile_trials}; 0: the search's trials alone)")
    p.add_argument("--refine-steps", type=int, default=d.refine_steps,
                   help="then this many gradient steps (sasmi fit-scene) on relief, albedo and altitude, kept if they "
                        f"lower the objective (default: {d.refine_steps})")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.realism.calibrate import CalibrateConfig, calibrate
    from sasmi.realism.preset_space import named_knobs

    cfg = CalibrateConfig(params=named_knobs(args.params), minutes=args.minutes, trials=args.trials, chips=args.chips,
                          size=args.size, spp=args.spp, sampler=args.sampler, step=args.step,
                          searches=args.searches, redraw_scenes=args.redraw_scenes, seed=args.seed,
                          variety_weight=args.variety_weight, distribution_weight=args.distribution_weight,
                          spread_correction=not args.plain_fid,
                          workers=args.workers, scheduler=args.scheduler,
                          final_chips=args.final_chips, contenders=args.contenders, profile_trials=args.profile_trials,
                          refine_steps=args.refine_steps)
    out = calibrate(args.real, args.preset, cfg, args.out, phi=args.phi)
    print(f"wrote {out}/preset.toml and {out}/report.md")
    return 0
