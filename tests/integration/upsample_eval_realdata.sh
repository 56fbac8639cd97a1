#!/usr/bin/env bash
# densemap-upsample-eval on real 64-beam scans (BALM): every 4th beam kept, upsampled back, and
# compared with all beams. Skips (exit 77) when the shared data is absent.
# Usage: upsample_eval_realdata.sh UPSAMPLE_EVAL_BIN SOURCE_DIR
set -euo pipefail
bin=$1
data=${DENSEMAP_DATA_DIR:-$2/../shared/data}/balm-realworld
if [ ! -d "$data" ]; then
  echo "skipped: $data is absent (set DENSEMAP_DATA_DIR)"
  exit 77
fi
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
"$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 --real "$data" --real-limit 3 \
  --threads 2 --json "$dir/r.json" >"$dir/out.txt" 2>"$dir/err.txt"
[ "$(grep -o '"dataset": "real:[^"]*"' "$dir/r.json" | wc -l)" -eq 2 ]
# The 64 x 2048 grid fits the sensor: few points share a pixel.
awk '/real scans projected/ { if ($(NF-7) * 10 > $5) bad = 1 } END { exit bad }' "$dir/err.txt"
echo "upsample eval real data: ok"
