#!/bin/sh
# The figures of docs/results.md, *Calibrated renders for an ATR*: does a calibrated preset's plain render serve an
# ATR better than its start's? For each PRESET (a name in scenes/ or a TOML file; a calibration's RUN/preset.toml),
# 400 target chips and 400 negatives of the same preset with its targets and companions left out (its own floors,
# so that "rendered floor" tells no class), then `sasmi atr-bench` on the seed-0 split: no, 10 and 40 real chips
# per class, the ways `real`, `alone` and `pretrain` (NAME/bench), then `mixed` and `replay` at 10 and 40
# (NAME/bench-mixed), 10 seeds each. Rerunning continues.
#
#     benchmarks/calibrate_atr.sh RUNS PRESET...
#     e.g. benchmarks/calibrate_atr.sh runs cylinder_chip muscle_paper runs/rocks-muscle/preset.toml
set -eu
RUNS=$1
shift
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips

[ -d "$RUNS/split" ] || $SASMI split $DATA --seed 0 --out "$RUNS/split"
for preset in "$@"; do
    case $preset in
        *.toml) file=$preset; name=$(basename "$(dirname "$preset")") ;;
        *) file=scenes/$preset.toml; name=$preset ;;
    esac
    out=$RUNS/atr-presets/$name
    mkdir -p "$out"
    .venv/bin/python benchmarks/preset_floors.py "$file" --out "$out/floors.toml"
    $SASMI render "$file" --count 400 --size 128 --out "$out/targets"
    $SASMI render "$out/floors.toml" --count 400 --size 128 --seed 1 --out "$out/floors"
    $SASMI atr-bench --real-train "$RUNS/split/train" --real-test "$RUNS/split/validation" \
        --synthetic "$out/targets" --synthetic-negatives "$out/floors" \
        --ways real alone pretrain --real-per-class 0 10 40 --out "$out/bench"
    $SASMI atr-bench --real-train "$RUNS/split/train" --real-test "$RUNS/split/validation" \
        --synthetic "$out/targets" --synthetic-negatives "$out/floors" \
        --ways real mixed replay --real-per-class 10 40 --out "$out/bench-mixed"
done
