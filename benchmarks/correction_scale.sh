#!/usr/bin/env bash
# The SAS GAN's correction scale (`[generator] correction_scale` of gan/recipes/real_levels.toml), chosen on
# the train side alone: the recipe's GAN retrained at each scale, everything else as in
# benchmarks/shipped_recipe.sh (its φ, its renders on drawn floors, seed 0, 1200 steps), 400 chips of each made
# as `sasmi generate` makes them, then the two-sample test over 5 classifier seeds, paired with the first scale:
# against the train side's own inner validation (`sasmi split` of the train side, by scene group), which chose,
# and against the validation targets.
#
#   benchmarks/shipped_recipe.sh runs 20 0          # first: the split, φ, renders on drawn floors
#   benchmarks/correction_scale.sh [RUNS] [SCALE ...]       defaults: runs 4 2 8 16
#
# Each scale trains for about 17 minutes on 2 cores; rerunning continues where it stopped.
set -euo pipefail
runs=${1:-runs}
shift || true
if [ $# -gt 0 ]; then scales=("$@"); else scales=(4 2 8 16); fi
sasmi=${SASMI:-.venv/bin/sasmi}
python=${PYTHON:-.venv/bin/python}
steps=${STEPS:-1200}
src=$runs/shipped-recipe/train

[ -d "$runs/inner" ] || $sasmi split "$runs/split/train" --seed 0 --out "$runs/inner"
sets=()
for scale in "${scales[@]}"; do
    out=$runs/correction-$scale
    mkdir -p "$out"
    sed "s/^correction_scale = [0-9]*/correction_scale = $scale/" gan/recipes/real_levels.toml > "$out/recipe.toml"
    resume=(); [ -f "$out/sasgan/checkpoints/last.pt" ] && resume=(--resume)
    $sasmi train sasgan --recipe "$out/recipe.toml" --real "$runs/split/train/targets" --renders "$src/on_floors" \
        --phi "$src/phi" --size 128 --seed 0 --steps "$steps" --threads 2 --out "$out/sasgan" "${resume[@]}"
    [ -f "$out/targets/labels.jsonl" ] || $sasmi generate cylinder_chip --generator "$out/sasgan" --checkpoint last \
        --seabeds "$src/weights/seabeds.pt" --count 400 --seed 1 --out "$out/targets"
    sets+=("$out/targets")
done
$python benchmarks/two_sample_seeds.py --real "$runs/inner/validation/targets" --seeds 5 "${sets[@]}"
$python benchmarks/two_sample_seeds.py --real "$runs/split/validation/targets" --seeds 5 "${sets[@]}"
