#!/usr/bin/env bash
# Reproduces the committed ILN model (models/iln.pb, models/iln_golden.pb) from simulated data
# only, on CPU (about 90 minutes on 2 cores; wall-clock budgets, so a slower machine takes as
# long and trains fewer steps):
#   1. range images from densemap-sim: scenes outdoor + indoor, seeds 1..40 (train) and
#      101, 102 (test), 6 poses each; a 16 x 1024 input with 64 x 1024 and 128 x 2048 targets
#      (FOV +15..-15 deg, 80 m), and a wide sensor like BALM's OS0-64 reduced to every 4th beam:
#      16 x 2048 input, 64 x 2048 target (FOV +45.5..-40.45 deg, 50 m);
#   2. 45 min on the narrow data (Adam, L1, cosine lr 1e-3 -> 1e-5, seed 1);
#   3. 40 min more on both (lr 5e-4 -> 1e-5, seed 2);
#   4. export of the weights and of PyTorch's golden outputs for the C++ test.
# Usage: scripts/train-iln.sh WORK_DIR [MODEL_OUT [GOLDEN_OUT]]   (after scripts/build.sh and
# scripts/install-deps.sh --iln)
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/train-iln.sh WORK_DIR [MODEL_OUT [GOLDEN_OUT]]}
model_out=${2:-models/iln.pb}
golden_out=${3:-models/iln_golden.pb}
bin=${DENSEMAP_BUILD_DIR:-build}/bin
iln=(/usr/bin/python3 tools/iln/iln.py)
mkdir -p "$work"
seeds=1..40,101,102
echo "train-iln: exporting simulated range images to $work"
"$bin/densemap-upsample-eval" --scenes outdoor,indoor --seeds "$seeds" --scans 6 \
  --targets 64x1024,128x2048 --export "$work/narrow" >/dev/null
"$bin/densemap-upsample-eval" --scenes outdoor,indoor --seeds "$seeds" --scans 6 \
  --input 16x2048 --targets 64x2048 --fov-top 45.5 --fov-bottom -40.45 --max-range 50 \
  --export "$work/wide" >/dev/null
echo "train-iln: stage 1 (45 min)"
"${iln[@]}" train --data "$work/narrow" --model "$work/stage1.pt" --minutes 45 --lr 1e-3 \
  --lr-final 1e-5 --seed 1 | tee "$work/stage1.log"
echo "train-iln: stage 2 (40 min)"
both=(--data "$work/narrow,$work/wide" --input 16x1024,16x2048
      --target 64x1024,128x2048,64x2048)
"${iln[@]}" train "${both[@]}" --init "$work/stage1.pt" --model "$work/stage2.pt" --minutes 40 \
  --lr 5e-4 --lr-final 1e-5 --seed 2 | tee "$work/stage2.log"
"${iln[@]}" export "${both[@]}" --model "$work/stage2.pt" --out "$model_out" \
  --golden "$golden_out" \
  --provenance "scripts/train-iln.sh: simulated data only; $(grep -h 'trained' \
    "$work/stage1.log" "$work/stage2.log" | tr '\n' ' ')"
