#!/bin/sh
# The figures of docs/results.md, *The targets' place along range*, measured at commit 9bdeb39 (`git checkout
# 9bdeb39`, then this script), whose default knobs searched the rocks' size (benchmarks/calibrate_rocks.sh measures
# the command as it stands): `sasmi calibrate` there (its objective
# matching the target's offset along range on target chips, `targets.range_offset` among the default knobs, the
# targets' positions moving with the chip size) from muscle_paper (the paper's 6 m chip) and from the default start
# (cylinder_chip) to the MILCO train targets of the seed-0 split; 400 renders of each against the validation targets
# beside 400 of cylinder_chip: `sasmi stats --check`, the φ-FID ratio and the two-sample test, then the two-sample
# test of the target band alone, of the floor alone and of the whole chip; and the muscle_paper search's preset with
# its targets drawn as narrowly along range as the real ones (quartiles -11.2 to -8.5 px: -1.18 to -0.68 m on its
# 12.11 m chip), all else as calibrated.
#
#     benchmarks/calibrate_place.sh [RUNS] [MINUTES]        (defaults: runs 30)
set -eu
RUNS=${1:-runs}
MINUTES=${2:-30}
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips

[ -d "$RUNS/split" ] || $SASMI split $DATA --seed 0 --out "$RUNS/split"
$SASMI calibrate --real "$RUNS/split/train/targets" --preset muscle_paper --minutes "$MINUTES" \
    --out "$RUNS/place-muscle"
$SASMI calibrate --real "$RUNS/split/train/targets" --minutes "$MINUTES" --out "$RUNS/place-default"
for run in place-muscle place-default; do
    $SASMI render "$RUNS/$run/preset.toml" --count 400 --size 128 --out "$RUNS/$run/renders"
done
[ -d "$RUNS/cylinder-renders" ] || $SASMI render cylinder_chip --count 400 --size 128 --out "$RUNS/cylinder-renders"
$SASMI stats "$RUNS/split/validation/targets" "$RUNS/place-muscle/renders" "$RUNS/place-default/renders" \
    "$RUNS/cylinder-renders" --check || true
$SASMI evaluate --real "$RUNS/split/validation/targets" --out "$RUNS/place-muscle/two-sample" \
    --set muscle="$RUNS/place-muscle/renders" --set default="$RUNS/place-default/renders" \
    --set cylinder_chip="$RUNS/cylinder-renders"
# the place's spread: the muscle_paper search's preset with its targets drawn as narrowly as the real ones
sed 's/^x = {uniform = \[-1.856, 0.0\]}/x = {uniform = [-1.18, -0.68]}/' "$RUNS/place-muscle/preset.toml" \
    > "$RUNS/place-muscle/narrow.toml"
$SASMI render "$RUNS/place-muscle/narrow.toml" --count 400 --size 128 --out "$RUNS/place-muscle/narrow-renders"
# which part of the chip tells them: the target band alone, the floor alone, then the whole chip
for hide in floor target none; do
    .venv/bin/python benchmarks/two_sample_seeds.py --real "$RUNS/split/validation/targets" --seeds 2 --hide $hide \
        "$RUNS/cylinder-renders" "$RUNS/place-muscle/renders" "$RUNS/place-default/renders" \
        "$RUNS/place-muscle/narrow-renders"
done
