"""`sasmi fit-scene PRESET --phi RUN --real DIR --params a,b --steps N --out DIR`.

Adjust scale factors on a preset's parameters by gradient descent so that the φ of its renders is
distributed as the φ of real chips (means and spreads). Writes trajectory.csv, loss.png,
fitted.toml (a preset for `sasmi render`) and fit_scene.json. See docs/differentiable.md.
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    from sasmi.realism.fit_scene import FitConfig
    from sasmi.render.differentiable import PARAMETERS

    defaults = FitConfig()
    p = sub.add_parser("fit-scene", help="fit scene parameters to real chips through the differentiable render",
                       description=__doc__)
    p.add_argument("preset", type=Path, help="scene preset (TOML) to start from")
    p.add_argument("--phi", type=Path, required=True, metavar="RUN", help="a trained autoencoder run (φ)")
    p.add_argument("--real", type=Path, required=True, metavar="DIR", help="real chips, searched recursively")
    p.add_argument("--params", default=",".join(defaults.params),
                   help=f"comma-separated, from: {', '.join(PARAMETERS)} (default: {','.join(defaults.params)})")
    p.add_argument("--steps", type=int, default=defaults.steps, help="Adam steps")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--size", type=int, help="render size (default: the size the φ encoder was trained at)")
    p.add_argument("--spp", type=int, default=defaults.spp, help="samples per pixel")
    p.add_argument("--scenes", type=int, default=defaults.scenes,
                   help=f"scenes of the preset rendered per step (default: {defaults.scenes})")
    p.add_argument("--lr", type=float, default=defaults.lr,
                   help=f"Adam rate on log-scales (default: {defaults.lr})")
    p.add_argument("--spread-weight", type=float, default=defaults.spread_weight,
                   help="weight of the φ spreads' term beside the means' (default: "
                        f"{defaults.spread_weight}; 0: the mean φ alone)")
    p.add_argument("--seed", type=int, default=defaults.seed, help="preset draws and sample streams (default: 0)")
    p.add_argument("--no-speckle", dest="speckle", action="store_false",
                   help="fit noise-free renders (default: the preset's speckle and noise as fixed fields)")
    p.set_defaults(run=run_fit)


def run_fit(args: argparse.Namespace) -> int:
    from sasmi.realism.fit_scene import FitConfig, fit_to_real, parse_params

    cfg = FitConfig(params=parse_params(args.params), steps=args.steps, lr=args.lr, scenes=args.scenes,
                    spread_weight=args.spread_weight,
                    size=args.size, spp=args.spp, seed=args.seed, speckle=args.speckle)
    from sasmi.images import FolderLock

    lock = FolderLock(args.out, "running sasmi fit-scene")  # two fits would mix their trajectories
    try:
        out = fit_to_real(args.preset, args.phi, args.real, cfg, args.out)
    finally:
        lock.release()
    print(f"wrote {out}/fitted.toml, trajectory.csv, loss.png")
    return 0
