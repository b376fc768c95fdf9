#!/usr/bin/env bash
# On one GPU machine, one command: SAS GAN speed under bf16 and float32, then `sasmi fit` on the GPU
# for MINUTES at each seed side by side (one small GAN leaves most of the GPU idle), and each
# run's realism report on the validation chips.
#
#   benchmarks/gpu.sh DATA MINUTES RECIPE      (SEEDS="0 1 2" by default; SPEED=0: the fits alone)
#
# The GPU machine needs PyTorch but neither Mitsuba nor a package index: everything else comes with
# the checkout: .whl/ holds the sasmi wheel (`pip wheel --no-deps -w .whl .`),
# DATA holds what was made on a machine with Mitsuba: train/ and validation/ (real target chips, files not
# links) and, per seed S, seedS/phi (an autoencoder run) and seedS/renders (the fit's render set of
# that seed). The renders stage is marked done in each fresh fit run, so the fit starts with the GAN.
# Results land in $OUT (default /tmp/gpu_out): speed.txt, and per seed fitS.log and metricsS.json;
# each run's fit.json (seconds per stage) is printed.
set -u
repo=$(pwd)
data=$(realpath "${1:?DATA}")
minutes=${2:-9}
recipe=${3:-real_levels}
seeds=${SEEDS:-0 1 2}
out=${OUT:-/tmp/gpu_out}
device=${DEVICE:-cuda}  # DEVICE=cpu tries the script on a machine without a GPU (tiny MINUTES)
threads=$(( $(nproc) / $(wc -w <<<"$seeds") ))  # the CPU side of the fits shares the cores
mkdir -p "$out"

[ "$device" = cpu ] || nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1
cd /tmp  # not the checkout: its sasmi/ folder is not the installed package (gan/ lives beside it)
python3 -c "import torch, sasmi; print('torch', torch.__version__, torch.cuda.is_available() and torch.cuda.get_device_name())"

echo "== speed: bf16 and float32, the recipe's SAS GAN at 128², and generator inference at 256²"
[ "${SPEED:-1}" = 0 ] || timeout 150 python3 "$repo/benchmarks/gan.py" --devices $device --nets small --kinds sasgan \
    --recipe "$recipe" --train-steps ${STEPS:-100} 2>&1 | grep -v Warning | tee "$out/speed.txt"

echo "== sasmi fit on the GPU, $minutes minutes, --recipe $recipe, seeds $seeds side by side ($threads CPU threads each)"
for seed in $seeds; do
    run=/tmp/fit$seed  # a run folder already there (the script run again) resumes with the larger budget
    [ -f $run/fit.json ] || python3 - "$data" "$run" "$minutes" "$recipe" "$seed" <<'EOF'
import shutil, sys
from sasmi.realism.fit import FitPlan, State, with_defaults
data, run, minutes, recipe, seed = sys.argv[1:]
plan = with_defaults(FitPlan(real=f"{data}/train", out=run, phi_real=f"{data}/train", validation=f"{data}/validation",
                             minutes=float(minutes), seed=int(seed), recipe=recipe, phi=f"{data}/seed{seed}/phi"))
state = State(plan)  # a fresh run folder whose renders stage is the renders made with Mitsuba elsewhere
shutil.copytree(f"{data}/seed{seed}/renders", f"{run}/renders")
state.add("renders", 0.0, done=True)
EOF
    /tmp/site/bin/sasmi fit --real "$data/train" --phi-real "$data/train" --validation "$data/validation" \
        --out $run --phi "$data/seed$seed/phi" --recipe "$recipe" --minutes "$minutes" --seed $seed \
        --device $device --threads $threads 2>&1 | tr '\r' '\n' | grep -v "it/s\|img/s" > "$out/fit$seed.log" &
done
wait
for seed in $seeds; do
    grep "sasmi fit" "$out/fit$seed.log" | grep "step\|report\]" | tail -3
    cp /tmp/fit$seed/report/metrics.json "$out/metrics$seed.json"
    tr -d ' \n' < /tmp/fit$seed/fit.json | grep -o '"seconds":{[^}]*}'; echo
done
python3 - "$out" $seeds <<'EOF'
import json, sys
out, seeds = sys.argv[1], sys.argv[2:]
for seed in seeds:  # the realism report's headline metrics, one row per set
    m = json.load(open(f"{out}/metrics{seed}.json"))
    for key, r in m["realism"].items():
        t = m["target_preservation"].get(key, {})
        print(f"seed {seed} {key:<10} φ-FID ratio {r['fid_ratio']:.2f} ± {r['fid_ratio_std'] or 0:.2f}  "
              f"P {r['precision']:.2f}  R {r['recall']:.2f}  IoU {t.get('shadow_iou', float('nan')):.3f}  "
              f"centroid {t.get('centroid_error_px', float('nan')):.1f} px  lost {100 * t.get('lost', 0):.1f} %")
EOF
