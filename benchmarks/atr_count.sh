#!/usr/bin/env bash
# Does the ATR bench gain from more synthetic chips? COUNT target chips and COUNT `seafloor_only` negatives
# made by the held-out recipe's files (benchmarks/shipped_recipe.sh trains them on a split's train side),
# then `sasmi atr-bench` with the ways and counts of docs/results.md, *ATR bench*. Rerunning continues.
#
#   benchmarks/atr_count.sh [RUNS] [COUNT]      defaults: runs 10000
set -euo pipefail
runs=${1:-runs}
count=${2:-10000}
sasmi=${SASMI:-.venv/bin/sasmi}
w=$runs/shipped-recipe/train/weights
[ -f "$w/sasgan.pt" ] || { echo "$w/sasgan.pt: run benchmarks/shipped_recipe.sh $runs first" >&2; exit 2; }
$sasmi generate cylinder_chip --generator "$w/sasgan.pt" --seabeds "$w/seabeds.pt" --count "$count" --seed 1 \
    --workers 2 --out "$runs/shipped-recipe/targets-$count"
$sasmi generate seafloor_only --generator "$w/sasgan.pt" --seabeds "$w/seabeds.pt" --count "$count" --seed 2 \
    --workers 2 --out "$runs/shipped-recipe/negatives-$count"
$sasmi atr-bench --real-train "$runs/split/train" --real-test "$runs/split/validation" \
    --synthetic "$runs/shipped-recipe/targets-$count" --synthetic-negatives "$runs/shipped-recipe/negatives-$count" \
    --ways real alone pretrain replay --real-per-class 0 10 40 --out "$runs/atr-shipped-recipe-$count"
