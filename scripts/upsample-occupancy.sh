#!/usr/bin/env bash
# The upsampling occupancy experiment (dissertation Sec. 4.4.5), reproducible: an outdoor sequence
# is simulated with a 16-beam sensor (with dense-oracle labels at 0.2 m, 4x its beams and
# columns) and with a true 64-beam sensor from the same poses; raycast maps are built from the
# 16-beam scans as they are, upsampled to 64 x 1024 by nearest, bilinear and ILN, and from the
# 64-beam scans, all scored on the same labels. Tables and JSON go to OUT_DIR.
# Usage: scripts/upsample-occupancy.sh OUT_DIR [MODEL]   (after scripts/build.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/upsample-occupancy.sh OUT_DIR [MODEL]}
model=${2:-models/iln.pb}
bin=${DENSEMAP_BUILD_DIR:-build}/bin
mkdir -p "$out"
common=(--scene outdoor --sensor vlp16 --columns 1024 --max-range 50 --scans 20)
echo "upsample-occupancy: simulating the 16-beam and 64-beam sequences"
"$bin/densemap-sim" --out "$out/s16" "${common[@]}" --oracle-factor 4 --oracle-resolutions 0.2 \
  --gt-resolution 0 >/dev/null
"$bin/densemap-sim" --out "$out/s64" "${common[@]}" --beams 64 --gt-resolution 0 >/dev/null
eval=(--protocol oracle --resolution 0.2 --max-range 50 --method raycast)
run() {  # NAME ARGS...
  local name=$1
  shift
  echo "upsample-occupancy: $name"
  "$bin/densemap-eval" "${eval[@]}" "$@" --json "$out/$name.json" | tee "$out/$name.txt"
}
run 16beam --data "$out/s16"
for method in nearest bilinear iln; do
  run "16to64_$method" --data "$out/s16" --upsample "$method" --upsample-model "$model" \
    --upsample-input 16x1024 --upsample-output 64x1024
done
run 64beam --data "$out/s64" --labels "$out/s16/oracle_0.2.bt"
echo "upsample-occupancy: AUC / MSE / acc_occupied / acc_free per row"
for name in 16beam 16to64_nearest 16to64_bilinear 16to64_iln 64beam; do
  printf '%-18s ' "$name"
  grep -o '"auc": [0-9.]*\|"mse": [0-9.]*\|"acc_occupied": [0-9.]*\|"acc_free": [0-9.]*' \
    "$out/$name.json" | awk '{ printf "%s %s  ", $1, $2 } END { print "" }'
done
