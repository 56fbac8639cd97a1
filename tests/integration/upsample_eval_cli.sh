#!/usr/bin/env bash
# densemap-upsample-eval end to end on one simulated scan: a result per method and target grid,
# sane metrics, ILN with the committed model, and clear errors for bad options or a bad model.
# Usage: upsample_eval_cli.sh UPSAMPLE_EVAL_BIN SOURCE_DIR
set -euo pipefail
bin=$1
model=$2/models/iln.pb
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
"$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024,128x2048 --threads 2 \
  --json "$dir/r.json" >"$dir/out.txt" 2>/dev/null
[ "$(grep -o '"method": "[a-z]*"' "$dir/r.json" | wc -l)" -eq 4 ]
grep -o '"iou": [0-9.]*' "$dir/r.json" | awk '{ if ($2 <= 0.05 || $2 > 1) bad = 1 } END { exit bad }'
grep -o '"mae": [0-9.]*' "$dir/r.json" | awk '{ if ($2 <= 0 || $2 > 5) bad = 1 } END { exit bad }'
# Training data export: one file per pose and grid, listed in index.csv, of rows*cols floats.
# Seeds as a range: 3..4 is seeds 3 and 4.
"$bin" --scenes indoor --seeds 3..4 --scans 2 --targets 64x1024 --threads 2 --export "$dir/data" \
  >/dev/null 2>&1
[ "$(tail -n +2 "$dir/data/index.csv" | wc -l)" -eq 8 ]
[ "$(stat -c %s "$dir/data/indoor_4_1_64x1024.f32")" -eq $((64 * 1024 * 4)) ]
[ "$(stat -c %s "$dir/data/indoor_3_0_16x1024.f32")" -eq $((16 * 1024 * 4)) ]
# ILN with the committed model: a result with sane metrics.
"$bin" --scenes indoor --seeds 9 --scans 1 --targets 64x1024 --methods iln --model "$model" \
  --threads 2 --json "$dir/iln.json" >/dev/null 2>&1
grep -q '"method": "iln"' "$dir/iln.json"
grep -o '"iou": [0-9.]*' "$dir/iln.json" | awk '{ if ($2 <= 0.05 || $2 > 1) bad = 1 } END { exit bad }'
if "$bin" --methods iln --model "$dir/none.pb" --scans 1 2>"$dir/err.txt" >/dev/null; then exit 1; fi
grep -q "cannot open ILN weights file" "$dir/err.txt"
head -c 100 "$model" >"$dir/cut.pb"
if "$bin" --methods iln --model "$dir/cut.pb" --scans 1 2>"$dir/err.txt" >/dev/null; then exit 1; fi
grep -q "cut.pb" "$dir/err.txt"
if "$bin" --methods bicubic --scans 1 2>"$dir/err.txt" >/dev/null; then exit 1; fi
grep -q "unknown interpolation" "$dir/err.txt"
if "$bin" --targets 64by1024 --scans 1 2>"$dir/err.txt" >/dev/null; then exit 1; fi
grep -q "ROWSxCOLS" "$dir/err.txt"
for seeds in 1..40x 1.40 5..2 x; do
  if "$bin" --seeds "$seeds" --scans 1 2>"$dir/err.txt" >/dev/null; then exit 1; fi
  grep -q "not a number or a range" "$dir/err.txt"
done
echo "upsample eval CLI: ok"
