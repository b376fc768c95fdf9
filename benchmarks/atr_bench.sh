#!/usr/bin/env bash
# The ATR figures of docs/results.md: one `sasmi fit` of the default recipe on a split of the shared
# chips, rendered seafloor as synthetic negatives, then `sasmi atr-bench` with the fit's renders and
# its translations as the synthetic targets, every way of using them, on the validation side.
#
#   benchmarks/atr_bench.sh [RUNS] [MINUTES] [SPLIT_SEED]      (defaults: runs 20 0)
#
# Rerunning continues: the fit, the renders and each bench resume where they stopped.
set -euo pipefail
runs=${1:-runs}
minutes=${2:-20}
seed=${3:-0}
sasmi=${SASMI:-.venv/bin/sasmi}
chips=${CHIPS:-../shared/data/sonar-chips}

[ -d "$runs/split" ] || $sasmi split "$chips" --seed "$seed" --out "$runs/split"
$sasmi fit --real "$runs/split/train/targets" --phi-real "$runs/split/train" --minutes "$minutes" --size 128 \
    --seed 0 --out "$runs/fit$minutes"
$sasmi render seafloor_only --count 400 --size 128 --seed 1 --out "$runs/negatives"
for stage in translated renders; do
    $sasmi atr-bench --real-train "$runs/split/train" --real-test "$runs/split/validation" \
        --synthetic "$runs/fit$minutes/$stage" --synthetic-negatives "$runs/negatives" --out "$runs/atr-$stage"
done
