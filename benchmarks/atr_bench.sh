#!/usr/bin/env bash
# The ATR figures of docs/results.md: one `sasmi fit` of the default recipe on a split of the shared
# chips; synthetic negatives made by the same pipeline as the synthetic targets (seafloor_only
# renders laid on the fit's real train floors and translated by its GAN) and, for comparison,
# plain rendered seafloor; then `sasmi atr-bench`, every way of using them, on the validation side.
#
#   benchmarks/atr_bench.sh [RUNS] [MINUTES] [SPLIT_SEED] [BENCHES]
#   defaults: runs 20 0 "translated:gan translated:rendered renders:rendered"
#
# Rerunning continues: the fit, the negatives and each bench resume where they stopped.
set -euo pipefail
runs=${1:-runs}
minutes=${2:-20}
seed=${3:-0}
benches=${4:-"translated:gan translated:rendered renders:rendered"}
sasmi=${SASMI:-.venv/bin/sasmi}
chips=${CHIPS:-../shared/data/sonar-chips}
fit=$runs/fit-$minutes

[ -d "$runs/split" ] || $sasmi split "$chips" --seed "$seed" --out "$runs/split"
$sasmi fit --real "$runs/split/train/targets" --phi-real "$runs/split/train" --minutes "$minutes" --size 128 \
    --seed 0 --out "$fit"
$sasmi render seafloor_only --count 400 --size 128 --seed 1 --out "$runs/negatives"
$sasmi generate seafloor_only --generator "$fit/sasgan" --count 400 --size 128 --seed 1 \
    --floors "$runs/split/train/seafloor" --real "$runs/split/train/targets" --out "$runs/negatives-gan"
for bench in $benches; do
    stage=${bench%%:*}; kind=${bench##*:}
    negatives=$runs/negatives; [ "$kind" = gan ] && negatives=$runs/negatives-gan
    $sasmi atr-bench --real-train "$runs/split/train" --real-test "$runs/split/validation" \
        --synthetic "$fit/$stage" --synthetic-negatives "$negatives" --out "$runs/atr-$stage-$kind"
done
