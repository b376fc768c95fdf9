"""A calibrated preset with another preset's kinds of target, at the same size in pixels.

    python benchmarks/target_kinds.py runs/calibrate-muscle-length/preset.toml cylinder_chip --out KINDS.toml

`sasmi calibrate` scales the start's targets but cannot add kinds: from `muscle_paper` (one cylinder) every render
shows a cylinder. This writes the calibrated preset with the [[targets]] kinds of a second preset (`cylinder_chip`:
cylinders, spheres, blocks, tyres, cones, boulders), every size times the ratio of the two chip sizes so that each
kind keeps its size in pixels, placed where the calibrated preset places its first kind (its `x` and `y`), and
everything else as calibrated: renders of the two presets then differ by the kinds of target alone
(docs/results.md, *Calibration*).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def with_kinds(calibrated: dict, kinds: dict) -> dict:
    """`calibrated` with the [[targets]] kinds of `kinds`, scaled by the ratio of their chip sizes and placed as
    `calibrated`'s first kind."""
    from sasmi.realism.preset_space import apply, centre, preset_value

    ratio = centre(preset_value(calibrated, "sonar", "chip_size")) / centre(preset_value(kinds, "sonar", "chip_size"))
    scaled = apply({"sonar": calibrated.get("sonar", {}), "targets": kinds["targets"]}, {"targets.size": ratio})
    place = {key: value for key, value in calibrated.get("targets", [{}])[0].items() if key in ("x", "y")}
    targets = [{**kind, **place} for kind in scaled["targets"]]
    described = {"description": f"{calibrated.get('description', 'calibrated')}; targets of another preset's kinds"}
    return {**calibrated, **described, "targets_per_chip": kinds.get("targets_per_chip", 1), "targets": targets}


def main(argv: list[str] | None = None) -> int:
    from sasmi.errors import SasmiError
    from sasmi.images import write_text
    from sasmi.realism.fit_scene import preset_toml
    from sasmi.scene.preset import Preset, load_preset

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("preset", help="the calibrated preset (a path or a shipped preset's name)")
    parser.add_argument("kinds", help="the preset whose [[targets]] kinds to draw")
    parser.add_argument("--out", type=Path, required=True, help="the preset to write (.toml)")
    args = parser.parse_args(argv)
    try:
        calibrated, kinds = load_preset(args.preset).raw, load_preset(args.kinds).raw
        if not kinds.get("targets"):
            raise SasmiError(f"{args.kinds}: no [[targets]] kinds to take")
        raw = with_kinds(calibrated, kinds)
        Preset.from_dict(raw)  # the result is a valid preset before anything is written
        write_text(args.out, f"# {args.preset} with the kinds of target of {args.kinds}\n" + preset_toml(raw))
    except SasmiError as e:
        print(f"target_kinds: error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
