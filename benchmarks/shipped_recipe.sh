#!/usr/bin/env bash
# The held-out figures of docs/models.md: the shipped weights' recipe (benchmarks/reference_weights.py)
# retrained on the train side of a split alone, then its chips, made as `sasmi generate` makes them
# with the shipped weights, measured on the validation side: φ-FID ratio and two-sample test in that
# recipe's own train-only φ, beside a `sasmi fit` of the same split (benchmarks/atr_bench.sh makes it),
# and the ATR bench with its synthetic targets and negatives.
#
#   benchmarks/shipped_recipe.sh [RUNS] [MINUTES] [SPLIT_SEED]      defaults: runs 20 0
#
# Rerunning continues: every stage resumes where it stopped.
set -euo pipefail
runs=${1:-runs}
minutes=${2:-20}
seed=${3:-0}
sasmi=${SASMI:-.venv/bin/sasmi}
python=${PYTHON:-.venv/bin/python}
chips=${CHIPS:-../shared/data/sonar-chips}
fit=$runs/fit-$minutes
out=$runs/shipped-recipe
w=$out/train/weights

[ -d "$runs/split" ] || $sasmi split "$chips" --seed "$seed" --out "$runs/split"
$python benchmarks/reference_weights.py --chips "$runs/split/train" --out "$out/train"
$sasmi generate cylinder_chip --generator "$w/sasgan.pt" --seabeds "$w/seabeds.pt" --count 400 --seed 1 \
    --out "$out/targets"
$sasmi generate seafloor_only --generator "$w/sasgan.pt" --seabeds "$w/seabeds.pt" --count 400 --seed 2 \
    --out "$out/negatives"
# the same generator on real floors: the train side's seafloor chips, as a user with floor chips of the sonar
$sasmi generate cylinder_chip --generator "$w/sasgan.pt" --floors "$runs/split/train/seafloor" \
    --real "$runs/split/train/targets" --count 400 --seed 1 --out "$out/targets-on-floors"
$sasmi generate seafloor_only --generator "$w/sasgan.pt" --floors "$runs/split/train/seafloor" \
    --real "$runs/split/train/targets" --count 400 --seed 2 --out "$out/negatives-on-floors"
sets=(--set "shipped_recipe=$out/targets" --set "renders_on_seabeds=$out/train/on_floors")
[ -d "$fit/translated" ] && sets+=(--set "fit=$fit/translated" --set "fit_on_floors=$fit/on_floors")
$sasmi evaluate --real "$runs/split/validation/targets" --phi "$w/phi.pt" "${sets[@]}" --bootstrap 100 \
    --out "$out/report"
$sasmi evaluate --real "$runs/split/validation/targets" --phi "$w/phi.pt" --set "shipped_recipe=$out/targets" \
    --set "on_real_floors=$out/targets-on-floors" --bootstrap 100 --out "$out/report-floors"
$sasmi atr-bench --real-train "$runs/split/train" --real-test "$runs/split/validation" \
    --synthetic "$out/targets" --synthetic-negatives "$out/negatives" --out "$runs/atr-shipped-recipe"
$sasmi atr-bench --real-train "$runs/split/train" --real-test "$runs/split/validation" \
    --synthetic "$out/targets-on-floors" --synthetic-negatives "$out/negatives-on-floors" \
    --out "$runs/atr-shipped-recipe-floors"
