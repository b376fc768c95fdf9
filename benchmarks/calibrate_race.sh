#!/bin/sh
# The figures of docs/results.md, *Searches that race*: the default `sasmi calibrate` (two searches racing over the
# first half of the time, the lower then continuing alone) to the MILCO train targets of the seed-0 split, as a user
# first runs it (from cylinder_chip, the default knobs), once per --seed; 400 renders of each against the validation
# targets beside 400 of cylinder_chip: `sasmi stats --check`, the φ-FID ratio and the two-sample test, then the
# two-sample test of the floor alone and of the whole chip (benchmarks/calibrate_rocks.sh: one search each).
#
#     benchmarks/calibrate_race.sh [RUNS] [MINUTES] [SEED...]        (defaults: runs 30 1 0)
set -eu
RUNS=${1:-runs}
MINUTES=${2:-30}
[ $# -gt 2 ] && shift 2 || set -- 1 0
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips

[ -d "$RUNS/split" ] || $SASMI split $DATA --seed 0 --out "$RUNS/split"
[ -d "$RUNS/cylinder-renders" ] || $SASMI render cylinder_chip --count 400 --size 128 --out "$RUNS/cylinder-renders"
for seed in "$@"; do
    run=$RUNS/race-$seed
    $SASMI calibrate --real "$RUNS/split/train/targets" --minutes "$MINUTES" --seed "$seed" --out "$run"
    $SASMI render "$run/preset.toml" --count 400 --size 128 --out "$run/renders"
    $SASMI stats "$RUNS/split/validation/targets" "$run/renders" "$RUNS/cylinder-renders" --check || true
    $SASMI evaluate --real "$RUNS/split/validation/targets" --out "$run/two-sample" \
        --set calibrated="$run/renders" --set cylinder_chip="$RUNS/cylinder-renders"
    for hide in target none; do
        .venv/bin/python benchmarks/two_sample_seeds.py --real "$RUNS/split/validation/targets" --seeds 2 \
            --hide $hide "$RUNS/cylinder-renders" "$run/renders"
    done
done
