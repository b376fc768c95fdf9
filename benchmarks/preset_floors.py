"""A preset's own floors: the preset with every table that draws an object left out.

    python benchmarks/preset_floors.py runs/calibrate/preset.toml --out FLOORS.toml

Negatives for an ATR made from the same preset as its targets (benchmarks/calibrate_atr.sh): the same sonar,
seabed and gray levels, no target and no companion, so that a rendered floor tells no class.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

OBJECTS = ("targets", "targets_per_chip", "target_grid", "companions")


def floors(raw: dict, name: str) -> dict:
    """`raw` without its targets and companions."""
    kept = {key: value for key, value in raw.items() if key not in OBJECTS}
    return {**kept, "description": f"the floors of {name}"}


def main(argv: list[str] | None = None) -> int:
    from sasmi.errors import SasmiError
    from sasmi.images import write_text
    from sasmi.realism.fit_scene import preset_toml
    from sasmi.scene.preset import Preset, load_preset

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("preset", help="a preset (a path or a shipped preset's name)")
    parser.add_argument("--out", type=Path, required=True, help="the preset to write (.toml)")
    args = parser.parse_args(argv)
    try:
        raw = floors(load_preset(args.preset).raw, args.preset)
        Preset.from_dict(raw)  # the result is a valid preset before anything is written
        write_text(args.out, f"# the floors of {args.preset}: its targets and companions left out\n" + preset_toml(raw))
    except SasmiError as e:
        print(f"preset_floors: error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
