#!/usr/bin/env bash
# densemap-upsample-eval on real 64-beam scans (BALM): every 4th and every 2nd beam kept,
# upsampled back and compared with all beams, per split, on evenly spread beams and on the
# sensor's beam table; the table estimated from the scans; the export for training. Skips
# (exit 77) when the shared data is absent.
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
even_collisions=$(awk '/real scans projected/ { print $(NF-7) }' "$dir/err.txt")

# The committed beam table: fewer points share a pixel than with evenly spread beams; two
# splits x two reductions x two methods.
table=$2/config/sensors/balm-os0-64.beams
"$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 --real "$data" --real-limit 3 \
  --real-beams "$table" --real-splits train:0-1,test:2-2 --reduce 4,2 --threads 2 \
  --export-real "$dir/export" --json "$dir/t.json" >"$dir/out.txt" 2>"$dir/err.txt"
[ "$(grep -o '"dataset": "real:[^"]*:test:every2"' "$dir/t.json" | wc -l)" -eq 2 ]
[ "$(grep -o '"dataset": "real:[^"]*"' "$dir/t.json" | wc -l)" -eq 8 ]
grep -q "(real test 2-2, every 4-th beam)" "$dir/out.txt"
table_collisions=$(awk '/real scans projected/ { print $(NF-7) }' "$dir/err.txt")
[ "$table_collisions" -lt "$even_collisions" ]
# The export holds the 3 scans' full images and the table, for tools/iln.
[ "$(tail -n +2 "$dir/export/index.csv" | wc -l)" -eq 3 ]
[ "$(stat -c %s "$dir/export/real_0.f32")" -eq $((64 * 2048 * 4)) ]
grep -q beams_64.txt "$dir/export/index.csv"

# Estimated from 20 scans (3 are too few: k-means settles in a wrong split), the table is the
# committed one (from 40) within 0.5 deg per beam.
"$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 --real "$data" --real-limit 20 \
  --estimate-beams "$dir/beams.txt" --threads 2 >/dev/null 2>&1
paste <(grep -v '^#' "$dir/beams.txt") <(grep -v '^#' "$table") |
  awk '{ d = $1 - $2; if (d < -0.5 || d > 0.5) bad = 1; n++ } END { exit bad || n != 64 }'
# Bad splits and tables: clear errors.
if "$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 --real "$data" \
  --real-limit 1 --real-splits "test:3" >/dev/null 2>"$dir/err.txt"; then exit 1; fi
grep -q "NAME:FIRST-LAST" "$dir/err.txt"
printf '20\n20\n10\n' >"$dir/bad.txt"
if "$bin" --scenes outdoor --seeds 7 --scans 1 --targets 64x1024 --real "$data" \
  --real-limit 1 --real-beams "$dir/bad.txt" >/dev/null 2>"$dir/err.txt"; then exit 1; fi
grep -q "decrease" "$dir/err.txt"
echo "upsample eval real data: ok"
