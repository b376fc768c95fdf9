#!/bin/sh
# One variant of the default `sasmi calibrate` command (FLAGS added to it) to the MILCO train targets of the seed-0
# split, from each START at each SEED (the command as a user first runs it starts from cylinder_chip), each judged on
# the validation targets by benchmarks/judge_calibration.sh. --profile-trials 0: the profiles judge the calibrated
# knobs after they are chosen and change no preset (rerun a folder without it for the report's full tables).
#
#     benchmarks/calibrate_variant.sh RUNS MINUTES NAME "FLAGS" START:SEED ...
#     (folders RUNS/NAME-START-SEED; e.g. benchmarks/calibrate_variant.sh runs 30 chips64 "--chips 64" cylinder_chip:1)
set -eu
RUNS=$1
MINUTES=$2
NAME=$3
FLAGS=$4
shift 4
SASMI=.venv/bin/sasmi
DATA=../shared/data/sonar-chips

[ -d "$RUNS/split" ] || $SASMI split $DATA --seed 0 --out "$RUNS/split"
[ -d "$RUNS/cylinder-renders" ] || $SASMI render cylinder_chip --count 400 --size 128 --out "$RUNS/cylinder-renders"
for start_seed in "$@"; do
    start=${start_seed%:*}
    seed=${start_seed#*:}
    run=$RUNS/$NAME-$start-$seed
    # FLAGS unquoted on purpose: they are split into the command's arguments
    $SASMI calibrate --real "$RUNS/split/train/targets" --preset "$start" --minutes "$MINUTES" --seed "$seed" \
        $FLAGS --profile-trials 0 --out "$run"
    benchmarks/judge_calibration.sh "$RUNS" "$run"
done
