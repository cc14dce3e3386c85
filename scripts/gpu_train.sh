#!/usr/bin/env bash
# A bounded training run on a CUDA machine, resuming a run folder, then the GPU
# extraction timing; what it makes is copied to $OUT (or outputs/gpu).
#
#   scripts/gpu_train.sh [RUN] [SECONDS]
#
# RUN      run folder to resume (default training/lburst-b5-lite-ap, the run of the shipped
#          lburst-b5-lite: the light network distilled
#          from the shipped lburst-b5); a new folder starts the 'lite' preset (or, with
#          LBURST_ARCH=lburst, the recipe of the shipped lburst-b5: the 'aligned' preset with
#          --rel-base 0.35 and --spread-weight 1, from the shipped lburst-b5)
# SECONDS  training time budget (default 420; the run checkpoints every minute)
#
# Training photos: $LBURST_TRAIN_DATA, else data/train512 (a git-ignored copy of
# $LBURST_SHARED/data/train512; its validation tenth is left out by lburst train).
# Needs torch, numpy, opencv, tqdm, scikit-image on the machine; lburst runs from the
# checkout (PYTHONPATH), nothing is installed.  Writes to $OUT: last.pt, log.csv,
# config.json, snapshots.tar (the run's snapshots), extract_speed.json (one burst per call),
# extract_speed_batch8.json (8 bursts per call), train.log.
# LBURST_DEVICE=cpu LBURST_SPEED=0 runs the same on a CPU (a check of the script).
set -euo pipefail
cd "$(dirname "$0")/.."
run=${1:-training/lburst-b5-lite-ap}
budget=${2:-420}
data=${LBURST_TRAIN_DATA:-data/train512}
device=${LBURST_DEVICE:-cuda}
out=${OUT:-outputs/gpu}
mkdir -p "$out"
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
python3 - <<EOF
import torch
print("torch", torch.__version__, "cuda", torch.cuda.is_available(),
      torch.cuda.get_device_name(0) if torch.cuda.is_available() else "")
EOF
workers=$(( $(nproc) > 2 ? $(nproc) - 2 : 1 ))
if [ -f "$run/last.pt" ]; then
  start=(--resume)
else
  if [ "${LBURST_ARCH:-lite}" = lite ]; then
    start=(--preset lite --frames 5 --snapshot-every 250)
  else
    start=(--preset aligned --rel-base 0.35 --spread-weight 1 --init lburst/weights/lburst-b5.pt --frames 5 --snapshot-every 50)
  fi
fi
python3 -m lburst.cli train --data "$data" --out "$run" --device "$device" --workers "$workers" \
  --steps 100000 --checkpoint-every 60 --time-budget "$budget" "${start[@]}" 2>&1 | tr '\r' '\n' | tail -n 40 | tee "$out/train.log"
cp "$run/last.pt" "$run/log.csv" "$run/config.json" "$out/"
if [ -d "$run/snapshots" ]; then tar -cf "$out/snapshots.tar" -C "$run" snapshots; fi
[ "${LBURST_SPEED:-1}" = 0 ] && exit 0  # LBURST_SPEED=0: training only
python3 scripts/extract_speed.py --device "$device" --paths plain fast bf16 default lite --out "$out/extract_speed.json" 2>&1 | tail -n 20
python3 scripts/extract_speed.py --device "$device" --paths fast default lite --batch 8 --out "$out/extract_speed_batch8.json" 2>&1 | tail -n 20
