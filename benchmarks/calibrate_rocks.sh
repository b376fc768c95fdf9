#!/bin/sh
# The figures of docs/results.md, *The rocks' size kept*: `sasmi calibrate` as it stands (the rocks' size searched
# only where named, so that a search keeps the start's) to the MILCO train targets of the seed-0 split, as a user
# first runs it (from cylinder_chip, the default knobs; two searches, --seed 0 and 1) and from muscle_paper; 400
# renders of each against the validation targets beside 400 of cylinder_chip: `sasmi stats --check`, the φ-FID
# ratio and the two-sample test, then the two-sample test of the floor alone and of the whole chip. Where
# benchmarks/calibrate_place.sh has run in RUNS, its muscle_paper search (the rocks' size searched) joins them, and so
# does that search's preset with its rocks drawn as cylinder_chip's (0.08-0.45 m), all else as calibrated.
#
#     benchmarks/calibrate_rocks.sh [RUNS] [MINUTES]        (defaults: runs 30)
set -eu
RUNS=${1:-runs}
MINUTES=${2:-30}
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips

[ -d "$RUNS/split" ] || $SASMI split $DATA --seed 0 --out "$RUNS/split"
[ -d "$RUNS/cylinder-renders" ] || $SASMI render cylinder_chip --count 400 --size 128 --out "$RUNS/cylinder-renders"
for seed in 0 1; do
    run=$RUNS/default-rocks-$seed
    $SASMI calibrate --real "$RUNS/split/train/targets" --minutes "$MINUTES" --seed $seed --out "$run"
    benchmarks/judge_calibration.sh "$RUNS" "$run"
done
$SASMI calibrate --real "$RUNS/split/train/targets" --preset muscle_paper --minutes "$MINUTES" \
    --out "$RUNS/rocks-muscle"
$SASMI render "$RUNS/rocks-muscle/preset.toml" --count 400 --size 128 --out "$RUNS/rocks-muscle/renders"
SEARCHED=""
if [ -d "$RUNS/place-muscle/renders" ]; then
    sed 's/^rock_radius = .*/rock_radius = {uniform = [0.08, 0.45]}/' "$RUNS/place-muscle/preset.toml" \
        > "$RUNS/rocks-muscle/searched-redrawn.toml"
    $SASMI render "$RUNS/rocks-muscle/searched-redrawn.toml" --count 400 --size 128 \
        --out "$RUNS/rocks-muscle/searched-redrawn-renders"
    SEARCHED="$RUNS/place-muscle/renders $RUNS/rocks-muscle/searched-redrawn-renders"
fi
$SASMI stats "$RUNS/split/validation/targets" "$RUNS/rocks-muscle/renders" "$RUNS/cylinder-renders" $SEARCHED \
    --check || true
$SASMI evaluate --real "$RUNS/split/validation/targets" --out "$RUNS/rocks-muscle/two-sample" \
    --set rocks_kept="$RUNS/rocks-muscle/renders" --set cylinder_chip="$RUNS/cylinder-renders"
# which part of the chip tells them: the floor alone (the target band hidden), then the whole chip
for hide in target none; do
    .venv/bin/python benchmarks/two_sample_seeds.py --real "$RUNS/split/validation/targets" --seeds 2 --hide $hide \
        "$RUNS/cylinder-renders" "$RUNS/rocks-muscle/renders" $SEARCHED
done
