#!/usr/bin/env bash
# One lent GPU machine, one call: SAS GAN speed under bf16 and float32, then `sasmi fit` on the GPU
# for MINUTES and its realism report on the validation chips.
#
#   benchmarks/gpu.sh DATA MINUTES RECIPE      (SPEED=0: the fit alone)
#
# The device machine has PyTorch but no Mitsuba and no package index, so everything comes with the
# call (the device tool's `carry`): .whl/ holds the sasmi wheel (`pip wheel --no-deps -w .whl .`),
# DATA holds what was made on this machine: phi/ (an autoencoder run), renders/ (a render set of the
# fit's size, 400 chips), train/ and validation/ (real target chips, files not links). The renders
# stage is marked done in a fresh fit run, so the fit starts with the GAN. Results land in $OUT.
set -u
repo=$(pwd)
data=$(realpath "${1:?DATA}")
minutes=${2:-9}
recipe=${3:-real_levels}
out=${OUT:-/tmp/gpu_out}
device=${DEVICE:-cuda}  # DEVICE=cpu tries the script on a machine without a GPU (tiny MINUTES)
mkdir -p "$out"

[ "$device" = cpu ] || nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1
cd /tmp  # not the checkout: its sasmi/ folder is not the installed package (gan/ lives beside it)
python3 -c "import torch, sasmi; print('torch', torch.__version__, torch.cuda.is_available() and torch.cuda.get_device_name())"

echo "== speed: bf16 and float32, the recipe's SAS GAN at 128², and generator inference at 256²"
[ "${SPEED:-1}" = 0 ] || timeout 150 python3 "$repo/benchmarks/gan.py" --devices $device --nets small paper --kinds sasgan \
    --gan "$recipe" --train-steps ${STEPS:-100} 2>&1 | grep -v Warning | tee "$out/speed.txt"

echo "== sasmi fit on the GPU, $minutes minutes, --gan $recipe"
run=/tmp/fit
python3 - "$data" "$run" "$minutes" "$recipe" <<'EOF'
import shutil, sys
from sasmi.pipeline import FitPlan, State, with_defaults
data, run, minutes, recipe = sys.argv[1:]
plan = with_defaults(FitPlan(real=f"{data}/train", out=run, phi_real=f"{data}/train", validation=f"{data}/validation",
                             minutes=float(minutes), gan=recipe, phi=f"{data}/phi"))
state = State(plan)  # a fresh run folder whose renders stage is the renders made with Mitsuba elsewhere
shutil.copytree(f"{data}/renders", f"{run}/renders")
state.add("renders", 0.0, done=True)
EOF
/tmp/site/bin/sasmi fit --real "$data/train" --phi-real "$data/train" --validation "$data/validation" \
    --out $run --phi "$data/phi" --gan "$recipe" --minutes "$minutes" --device $device 2>&1 | tr '\r' '\n' | grep -v "it/s\|img/s" \
    | tee "$out/fit.log" | grep "sasmi fit"
cp $run/report/metrics.json "$out/metrics.json"
cp $run/fit.json "$out/fit.json"
mkdir -p "$out/sasgan/checkpoints"  # the trained generator, to translate and evaluate at home
cp $run/sasgan/config.json "$out/sasgan/" && cp $run/sasgan/checkpoints/last.pt "$out/sasgan/checkpoints/"

echo "== the same generator without the donors' levels (its own gray levels)"
python3 - "$run" "$device" <<'EOF'
import sys
from pathlib import Path
from sasmi.gan.generator import load_generator
from sasmi.gan.translate import translate_folder
run = Path(sys.argv[1])
generator = load_generator(run / "sasgan", sys.argv[2])
generator.donor_levels_after = False
translate_folder(generator, run / "renders", run / "translated_own")
EOF
/tmp/site/bin/sasmi evaluate --real "$data/validation" --set own=$run/translated_own --set donors=$run/translated \
    --phi "$data/phi" --out /tmp/report_own --device $device 2>&1 | tr '\r' '\n' | grep -v "it/s\|img/s" | tail -3
cp /tmp/report_own/metrics.json "$out/metrics_own.json"
python3 - "$out" <<'EOF'
import json, sys
for name in ("metrics.json", "metrics_own.json"):  # the realism goals of issue 12, one row per set
    m = json.load(open(f"{sys.argv[1]}/{name}"))
    for key, r in m["realism"].items():
        t = m["target_preservation"].get(key, {})
        print(f"{name:<17} {key:<10} φ-FID ratio {r['fid_ratio']:.2f} ± {r['fid_ratio_std'] or 0:.2f}  "
              f"P {r['precision']:.2f}  R {r['recall']:.2f}  IoU {t.get('shadow_iou', float('nan')):.3f}  "
              f"centroid {t.get('centroid_error_px', float('nan')):.1f} px  lost {100 * t.get('lost', 0):.1f} %")
EOF
