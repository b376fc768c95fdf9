#!/bin/sh
# A calibration judged on chips it never saw: 400 renders of RUN/preset.toml against the validation targets of the
# seed-0 split beside 400 of cylinder_chip (RUNS/cylinder-renders): `sasmi stats --check`, `sasmi evaluate` (φ-FID
# ratio, precision / recall, two-sample test; RUN/two-sample), then the two-sample test of the floor alone and of the
# whole chip over two classifier seeds. Used by benchmarks/calibrate_rocks.sh and benchmarks/calibrate_variant.sh.
#
#     benchmarks/judge_calibration.sh RUNS RUN
set -eu
RUNS=$1
run=$2
SASMI=.venv/bin/sasmi

$SASMI render "$run/preset.toml" --count 400 --size 128 --out "$run/renders"
$SASMI stats "$RUNS/split/validation/targets" "$run/renders" "$RUNS/cylinder-renders" --check || true
$SASMI evaluate --real "$RUNS/split/validation/targets" --out "$run/two-sample" \
    --set calibrated="$run/renders" --set cylinder_chip="$RUNS/cylinder-renders"
for hide in target none; do
    .venv/bin/python benchmarks/two_sample_seeds.py --real "$RUNS/split/validation/targets" --seeds 2 \
        --hide $hide "$RUNS/cylinder-renders" "$run/renders"
done
