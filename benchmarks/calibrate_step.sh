#!/bin/sh
# The figures of docs/results.md, *A smaller first step*: `sasmi calibrate --step 0.05` (CMA-ES begun at 0.05 of
# each knob's range, where the default is Optuna's 1/6) to the MILCO train targets of the seed-0 split, from each
# START at each SEED (the command as a user first runs it starts from cylinder_chip); 400 renders of each against the
# validation targets beside 400 of cylinder_chip: `sasmi stats --check`, the φ-FID ratio and the two-sample test, then
# the two-sample test of the floor alone and of the whole chip (benchmarks/calibrate_variant.sh).
# benchmarks/calibrate_rocks.sh runs the same at the default step.
#
#     benchmarks/calibrate_step.sh [RUNS] [MINUTES] [START:SEED ...]
#     (defaults: runs 30 cylinder_chip:1 cylinder_chip:0 muscle_paper:0; folders RUNS/step-START-SEED)
set -eu
RUNS=${1:-runs}
MINUTES=${2:-30}
[ $# -gt 2 ] && shift 2 || set -- cylinder_chip:1 cylinder_chip:0 muscle_paper:0
exec benchmarks/calibrate_variant.sh "$RUNS" "$MINUTES" step "--step 0.05" "$@"
