#!/usr/bin/env bash
# Reproduces the committed ILN model (models/iln.pb, models/iln_golden.pb) on CPU (about 2 h 30
# min on 2 cores; wall-clock budgets, so a slower machine takes as long and trains fewer steps):
#   1. range images from densemap-sim: scenes outdoor + indoor, seeds 1..40 (train) and
#      101, 102 (test), 6 poses each; a 16 x 1024 input with 64 x 1024 and 128 x 2048 targets
#      (FOV +15..-15 deg, 80 m), and a wide sensor like BALM's OS0-64 reduced to every 4th beam:
#      16 x 2048 input, 64 x 2048 target (FOV +45.5..-40.45 deg, 50 m);
#   2. 45 min on the narrow data (Adam, L1, cosine lr 1e-3 -> 1e-5, seed 1);
#   3. 40 min more on both (lr 5e-4 -> 1e-5, seed 2) — the simulated-only model;
#   4. real scans, self-supervised: BALM scans 20-59 (dataset indices 0-39; 52-59 held out for
#      validation) projected on the sensor's beam table (config/sensors/balm-os0-64.beams),
#      every 4th and every 2nd beam in, all 64 out. Scans 60-99 (indices 40-79) are the test
#      set: never exported, never trained on. 45 min on simulated + real data (each real pair
#      drawn 10x as often, lr 5e-4 -> 1e-5, seed 3), then 15 min (20x, lr 2e-4 -> 1e-6, seed 4);
#   5. export of the weights (with their provenance) and of PyTorch's golden outputs.
# Usage: scripts/train-iln.sh WORK_DIR [MODEL_OUT [GOLDEN_OUT]]   (after scripts/build.sh and
# scripts/install-deps.sh --iln). ILN_SIM_MODEL=FILE skips steps 1-3 and starts step 4 from
# that weights file (e.g. the simulated-only model of commit af68dc7). ILN_REAL_DATA (default
# ../shared/data/balm-realworld): without it the script stops after step 3.
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/train-iln.sh WORK_DIR [MODEL_OUT [GOLDEN_OUT]]}
model_out=${2:-models/iln.pb}
golden_out=${3:-models/iln_golden.pb}
real=${ILN_REAL_DATA:-${DENSEMAP_DATA_DIR:-../shared/data}/balm-realworld}
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
sim=(--data "$work/narrow,$work/wide" --input 16x1024,16x2048
     --target 64x1024,128x2048,64x2048)
if [ -n "${ILN_SIM_MODEL:-}" ]; then
  echo "train-iln: starting from $ILN_SIM_MODEL (steps 1-3 skipped)"
  start=$ILN_SIM_MODEL
  : >"$work/stage1.log"
  : >"$work/stage2.log"
else
  echo "train-iln: stage 1 (45 min)"
  "${iln[@]}" train --data "$work/narrow" --model "$work/stage1.pt" --minutes 45 --lr 1e-3 \
    --lr-final 1e-5 --seed 1 | tee "$work/stage1.log"
  echo "train-iln: stage 2 (40 min)"
  "${iln[@]}" train "${sim[@]}" --init "$work/stage1.pt" --model "$work/stage2.pt" \
    --minutes 40 --lr 5e-4 --lr-final 1e-5 --seed 2 | tee "$work/stage2.log"
  start=$work/stage2.pt
fi
if [ ! -d "$real" ]; then
  echo "train-iln: $real is absent: the model stays simulated-only" >&2
  "${iln[@]}" export "${sim[@]}" --model "$work/stage2.pt" --out "$model_out" \
    --golden "$golden_out" --provenance "scripts/train-iln.sh: simulated data only; $(grep -h \
      'trained' "$work/stage1.log" "$work/stage2.log" | tr '\n' ' ')"
  exit 0
fi
echo "train-iln: exporting real training scans (BALM 20-59 only) to $work/real"
"$bin/densemap-upsample-eval" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 \
  --real "$real" --real-first 0 --real-limit 40 --real-beams config/sensors/balm-os0-64.beams \
  --methods bilinear --export-real "$work/real" >/dev/null
both=(--data "$work/narrow,$work/wide,$work/real" --real-val 32-39
      --input 16x1024,16x2048,32x2048 --target 64x1024,128x2048,64x2048)
echo "train-iln: stage 3 (45 min, simulated + real)"
"${iln[@]}" train "${both[@]}" --real-weight 10 --init "$start" --model "$work/stage3.pt" \
  --minutes 45 --lr 5e-4 --lr-final 1e-5 --seed 3 | tee "$work/stage3.log"
echo "train-iln: stage 4 (15 min, real pairs 20x)"
"${iln[@]}" train "${both[@]}" --real-weight 20 --init "$work/stage3.pt" \
  --model "$work/stage4.pt" --minutes 15 --lr 2e-4 --lr-final 1e-6 --seed 4 \
  | tee "$work/stage4.log"
"${iln[@]}" export "${sim[@]}" --model "$work/stage4.pt" --out "$model_out" \
  --golden "$golden_out" \
  --provenance "scripts/train-iln.sh: simulated data (densemap-sim seeds 1..40; test seeds 101, \
102) and real BALM scans 20-59 (train 20-51, validation 52-59; scans 60-99 are the test set, \
never trained on), every 4th and 2nd beam in, 64 out, on config/sensors/balm-os0-64.beams; \
start: ${ILN_SIM_MODEL:-stages 1-2}; $(grep -h 'trained' "$work"/stage[1234].log | tr '\n' ' ')"
