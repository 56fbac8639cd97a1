#!/usr/bin/env bash
# End to end, as a user runs it: densemap-sim writes a sparse benchmark scene with dense-oracle
# labels; densemap-eval scores the five map kinds on them and writes JSON, ROC, reliability
# diagrams and slices.
# Usage: eval_oracle_cli.sh SIM_BIN EVAL_BIN
set -euo pipefail
sim=$1
evaluate=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT

"$sim" --out "$dir/scene" --scene structured --sensor os0-64 --columns 256 --scans 4 \
  --points-per-scan 1500 --max-range 8 --oracle-factor 2 --oracle-resolutions 0.2 \
  --gt-resolution 0 --threads 2 >/dev/null 2>&1
test -s "$dir/scene/oracle_0.2.bt"

"$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.2 --max-range 8 \
  --json "$dir/r.json" --roc "$dir/roc" --slice "$dir/slice" --reliability "$dir/rel" \
  --threads 2 >"$dir/out.txt" 2>/dev/null
[ "$(grep -o '"method": "[a-z_]*"' "$dir/r.json" | wc -l)" -eq 5 ]
grep -q '"method": "akimap_rays"' "$dir/r.json"
# Reliability: 10 bins per method, their counts summing to the test cells of each method.
[ "$(grep -c '^akimap_rays,' "$dir/rel.csv")" -eq 10 ]
awk -F, 'NR > 1 { n[$1] += $4 } END { for (m in n) if (n[m] != n["bgk"]) bad = 1; exit bad }' \
  "$dir/rel.csv"
grep -q 'ECE' "$dir/rel.svg"
grep -q '"protocol": "oracle"' "$dir/r.json"
# Every method ranks the labelled cells far better than chance.
grep -o '"auc": [0-9.]*' "$dir/r.json" | awk '{ if ($2 < 0.8) { print "auc " $2 " too low"; bad = 1 } }
  END { exit bad }'
for f in roc.svg roc_akimap.csv slice_akimap.png slice_akimap_rays.png slice_oracle.png; do
  test -s "$dir/$f"
done
# A kernel setting the maps do not have: a clear error, exit 1.
if "$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.2 --method bgkl \
  --kernel-set widht=3 2>"$dir/err.txt" >/dev/null; then
  echo "expected an error for an unknown kernel setting"
  exit 1
fi
grep -q "widht=3" "$dir/err.txt"
head -c 8 "$dir/slice_oracle.png" | od -An -c | grep -q 'P   N   G'

# The same scans densified (bilinear, 2x beams and columns) and scored on the same labels.
"$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.2 --max-range 8 --method raycast \
  --upsample bilinear --upsample-input 64x256 --upsample-output 127x512 --fov-top 45 \
  --fov-bottom -45 --labels "$dir/scene/oracle_0.2.bt" --json "$dir/up.json" --threads 2 \
  >/dev/null 2>&1
grep -o '"auc": [0-9.]*' "$dir/up.json" | awk '{ if ($2 < 0.8) bad = 1 } END { exit bad }'

# Labels at a resolution that was not written: a clear error, exit 1.
if "$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.1 2>"$dir/err.txt" >/dev/null; then
  echo "expected an error for missing labels"
  exit 1
fi
grep -q -- "--oracle-factor" "$dir/err.txt"
# A denser AKIMap free sampling gives a different map (more free samples), still a sound one.
"$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.2 --max-range 8 --method akimap \
  --akimap-free-step 0.25 --json "$dir/dense_free.json" --threads 2 >/dev/null 2>&1
auc() { grep -m1 -o '"auc": [0-9.]*' "$1" | awk '{ print $2 }'; }
[ "$(auc "$dir/dense_free.json")" != "$(auc "$dir/r.json")" ]
auc "$dir/dense_free.json" | awk '{ if ($1 < 0.8) bad = 1 } END { exit bad }'
if "$evaluate" --data "$dir/scene" --protocol oracle --resolution 0.2 --akimap-free-step 0 \
  >/dev/null 2>"$dir/err.txt"; then
  echo "expected an error for a zero free step"
  exit 1
fi
grep -q -- "--akimap-free-step" "$dir/err.txt"
echo "eval oracle CLI: ok"
