"""Does `sasmi calibrate` recover a known preset, and does its report say which knobs it cannot pin?

    python benchmarks/calibrate_recovery.py --out runs/calibrate-recovery [--minutes 20] [--chips 32]
                                            [--params a,b,...] [--profile-trials N] [--plain-fid] [--table-only]

The truth is `cylinder_chip` with five knobs moved (TRUTH); 200 of its renders at 128 px (seed 7)
stand in for real chips. `sasmi calibrate` starts from `cylinder_chip` itself, searches every default
knob (or those --params names, the rest held at the start's values: the truth's but for TRUTH's) for
--minutes, and the table compares each knob's calibrated value with the truth beside the report's verdict
on whether the chips pin it (RUN/calibrate/sensitivity.json: moved alone, and the best trials holding it
more than 15 % away, and its profile there, score worse on other draws). A second table takes the knobs
the renders see together (COMBINATIONS, then any other pair the report judges) and whether the report's
*moves with* names each pair, rising together for a ratio and falling for a product, and pins what the
pair makes together (RUN/calibrate/together.json). Rerunning continues the calibration and writes its report
again.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

START = "cylinder_chip"
TRUTH = {"sonar.chip_size": 30.0, "post.gain": 0.65, "post.speckle_looks": 4.0, "seafloor.rms_height": 0.03,
         "targets.size": 1.3}  # the start's: 24 m, 0.45, 6.5, 0.0175, 1
RECOVERED = 0.15  # within this share of the truth
# what the renders see of several knobs together: a target's size in pixels, the shadows' geometry in pixels,
# the grazing angle at the near edge, the floor's brightness
COMBINATIONS = {"target size : chip size": ("targets.size", "sonar.chip_size", -1),
                "altitude : chip size": ("sonar.altitude", "sonar.chip_size", -1),
                "altitude : near range": ("sonar.altitude", "sonar.near_range", -1),
                "gain x albedo": ("post.gain", "seafloor.albedo", 1)}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--minutes", type=float, default=20.0)
    p.add_argument("--chips", type=int, default=32, help="renders a trial (calibrate's --chips)")
    p.add_argument("--params", default="default",
                   help="knobs searched, comma-separated (calibrate's --params); the tables show the run's")
    p.add_argument("--profile-trials", type=int, help="calibrate's --profile-trials (default: its default)")
    p.add_argument("--plain-fid", action="store_true", help="calibrate's --plain-fid: the plain φ-FID ratio")
    p.add_argument("--table-only", action="store_true", help="print the tables of a finished run, calibrating no more")
    args = p.parse_args()

    from sasmi.errors import SasmiError
    from sasmi.realism.calibrate import CalibrateConfig, calibrate
    from sasmi.realism.fit_scene import preset_toml
    from sasmi.realism.preset_space import apply, centre, check_knobs, named_knobs, start_values
    from sasmi.renderset.write import RenderJob, render_set
    from sasmi.scene.preset import Preset, load_preset

    params = named_knobs(args.params)
    try:
        check_knobs(params)
    except SasmiError as e:
        p.error(str(e))
    start = load_preset(START)
    truth_raw = apply(start.raw, TRUTH)
    chips, run = args.out / "truth-chips", args.out / "calibrate"
    if not args.table_only:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "truth.toml").write_text(preset_toml(truth_raw))
        render_set(RenderJob(preset=Preset.from_dict(truth_raw, path=start.path), out=chips, count=200, seed=7,
                             size=128))
        cfg = CalibrateConfig(params=params, minutes=args.minutes, chips=args.chips,
                              spread_correction=not args.plain_fid)
        if args.profile_trials is not None:
            cfg = replace(cfg, profile_trials=args.profile_trials)
        calibrate(chips / "images", START, cfg, run)
    elif not (run / "sensitivity.json").is_file():
        sys.exit(f"{run}: no finished calibration; run without --table-only first")
    pins = json.loads((run / "sensitivity.json").read_text())
    params = tuple(json.loads((run / "calibrate.json").read_text())["identity"]["params"])  # the run's, as searched
    calibrated_raw = load_preset(run / "preset.toml").raw
    truth, got, before = (start_values(raw, params) for raw in (truth_raw, calibrated_raw, start.raw))
    for name, key in (("targets.size", "length"), ("targets.burial", "burial")):
        # start_values gives the factor 1 for any preset: compare the first target's field with the start's
        first = [raw["targets"][0].get(key) for raw in (start.raw, truth_raw, calibrated_raw)]
        if first[0]:
            before[name], truth[name], got[name] = (centre(v) / centre(first[0]) for v in first)
    for table in (before, truth, got):  # targets.size scales burial too: the burial knob is what is left
        if "targets.burial" in table:
            table["targets.burial"] /= table.get("targets.size", 1.0)
    print("| knob | start | truth | calibrated | off by | pinned by the chips |\n|---|---|---|---|---|---|")
    misses, untold = [], []
    verdicts = {True: "yes", False: "no", None: "cannot tell"}
    for name in params:
        off = abs(got[name] - truth[name]) / max(abs(truth[name]), 1e-9)
        pinned = pins[name]["pinned"]
        if pinned and off > RECOVERED:
            misses.append(name)
        if pinned is None:
            untold.append(name)
        print(f"| {name} | {before[name]:.4g} | {truth[name]:.4g} | {got[name]:.4g} | "
              f"{'—' if math.isinf(off) else f'{off:.0%}'} | {verdicts[pinned]} |")
    print(f"pinned knobs off by more than {RECOVERED:.0%}: {', '.join(misses) or 'none'}; "
          f"{len(untold)} knobs the report cannot tell\n")
    # a ratio the renders see makes its knobs rise together along the objective's ridge, a product one fall as
    # the other rises: the report's *moves with* should name the pair with that sign, and RUN/together.json
    # judges what the chips pin of each pair it names; the pairs it names beyond COMBINATIONS follow them
    together = json.loads((run / "together.json").read_text()) if (run / "together.json").is_file() else {}
    rows = {label: row for label, row in COMBINATIONS.items() if {row[0], row[1]} <= set(params)}
    for label, pair in together.items():
        if not any({a, b} == set(pair["knobs"]) for a, b, _ in rows.values()):
            rows[label] = (*pair["knobs"], pair["power"])
    print("| knobs together | truth | calibrated | off by | report: moves with | pinned together |\n"
          "|---|---|---|---|---|---|")
    named, misses = 0, []
    for label, (a, b, power) in rows.items():
        t, g = (table[a] * table[b] ** power for table in (truth, got))
        r = dict(pins[a].get("moves_with", [])).get(b)
        right = r is not None and (r > 0) == (power < 0)
        named += right and label in COMBINATIONS
        seen = "not named" if r is None else f"{r:+.2f}{'' if right else ' (the wrong way)'}"
        # the report's pair may be the inverse ratio (b : a): the same verdict, the kind of pair must agree
        judged = [p for p in together.values() if set(p["knobs"]) == {a, b} and (p["power"] < 0) == (power < 0)]
        pinned = judged[0]["pinned"] if judged else "—"
        off = abs(g - t) / t
        if pinned is True and off > RECOVERED:
            misses.append(label)
        print(f"| {label} | {t:.4g} | {g:.4g} | {off:.0%} | {seen} | {verdicts.get(pinned, pinned)} |")
    physical = sum(label in COMBINATIONS for label in rows)
    print(f"pairs the report names as moving together, the way the renders see them: {named} of {physical}; "
          f"pairs pinned together off by more than {RECOVERED:.0%}: {', '.join(misses) or 'none'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
