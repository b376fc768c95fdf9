"""What the gain's swing from ping to ping does to a preset's chips: the preset as it is and with
`post.gain_swing = {uniform = [0, SWING]}`, 400 renders of each at 128 px against a folder of real chips:
`sasmi stats --check` (its *gain swing along track* row beside the real chips') and `sasmi evaluate` (φ-FID
ratio, precision and recall).

    .venv/bin/python benchmarks/gain_swing.py REAL PRESET [PRESET ...] [--swing 0.12] [--count 400] --out DIR

DIR gets NAME.toml and NAME-swing.toml, their renders, stats.md and evaluate/. Draw SWING so that the renders'
gain swing matches the chips you tune on (`sasmi stats TRAIN` prints theirs), then judge on chips kept out.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SASMI = str(Path(sys.executable).with_name("sasmi"))


def main() -> None:
    from sasmi.realism.fit_scene import preset_toml
    from sasmi.scene.preset import load_preset

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("real", help="real chips to judge the renders against (kept out of any tuning)")
    ap.add_argument("presets", nargs="+", help="preset names or files")
    ap.add_argument("--swing", type=float, default=0.12, help="each chip's gain swing drawn in [0, SWING] (0.12)")
    ap.add_argument("--count", type=int, default=400, help="renders of each preset (400)")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()

    args.out.mkdir(parents=True, exist_ok=True)
    sets = []
    for name in args.presets:
        preset = load_preset(name)
        stem = Path(name).parent.name if Path(name).name == "preset.toml" else Path(name).stem
        raw = dict(preset.raw, post={**preset.raw.get("post", {}), "gain_swing": {"uniform": [0.0, args.swing]}})
        for label, body in ((stem, preset.raw), (f"{stem}-swing", raw)):
            toml = args.out / f"{label}.toml"
            toml.write_text(preset_toml(body))
            renders = args.out / f"{label}-renders"
            subprocess.run([SASMI, "render", str(toml), "--count", str(args.count), "--size", "128",
                            "--out", str(renders)], check=True, stdout=subprocess.DEVNULL)
            sets.append((label, renders))
    stats = subprocess.run([SASMI, "stats", args.real, *(str(r) for _, r in sets), "--check"],
                           capture_output=True, text=True)
    (args.out / "stats.md").write_text(stats.stdout)
    print(stats.stdout)
    subprocess.run([SASMI, "evaluate", "--real", args.real, "--no-two-sample", "--out", str(args.out / "evaluate"),
                    *(a for label, r in sets for a in ("--set", f"{label}={r}"))], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    report = (args.out / "evaluate" / "report.md").read_text().splitlines()
    start = next(i for i, line in enumerate(report) if line.startswith("| set | images"))
    print("\n".join(report[start:start + 3 + len(sets)]))


if __name__ == "__main__":
    main()
