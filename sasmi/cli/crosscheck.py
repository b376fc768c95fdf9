"""`sasmi crosscheck PRESET --out DIR`: render one scene with Mitsuba and with POV-Ray, compare.

Writes mitsuba.png, povray.png, diff.png, side_by_side.png, scene.pov and metrics.json to DIR and
prints the metrics. Exit status 1 when a check fails. Needs Debian's povray (`make setup` installs
it).
"""
from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("crosscheck", help="render one scene with Mitsuba and POV-Ray and compare them",
                       description=__doc__)
    p.add_argument("preset", type=Path, help="scene preset (TOML), e.g. scenes/cylinder_chip.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument("--index", type=int, default=0, help="which scene of the preset")
    p.add_argument("--seed", type=int, default=0, help="preset seed, as in `sasmi render`")
    p.add_argument("--size", type=int, default=256, help="image size in pixels, a multiple of 16")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from sasmi.render import povray
    from sasmi.render.crosscheck import crosscheck, table, write
    from sasmi.errors import SasmiError
    from sasmi.render.llvm import versions
    from sasmi.scene.preset import load_preset

    if args.index < 0:
        raise SasmiError(f"--index {args.index}: must be >= 0")
    scene = load_preset(args.preset).sample(args.seed, args.index)
    result = crosscheck(scene, args.size)
    write(result, args.out, provenance={"preset": str(args.preset), "index": args.index, "seed": args.seed,
                                        "size": args.size, "povray": povray.version(), **versions()})
    print(f"sasmi crosscheck: {args.preset} scene {args.index} at {args.size}x{args.size} -> {args.out}")
    print(table(result.metrics))
    return 0 if result.metrics.passed else 1
