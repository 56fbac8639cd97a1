#!/usr/bin/env bash
# Issue 5's accuracy benchmark, reproducible: simulates the structured and unstructured scenes
# (12 scans x 3,500 points from 4 stations, 8 m range) with dense-oracle labels, then scores
# akimap, bgk, bgkl and raycast by the oracle protocol at 0.1 m and 0.05 m (10 seeds), writing
# tables, JSON, ROC curves (SVG) and z = 1 m slices (PNG) into OUT_DIR.
# Usage: scripts/akimap-benchmark.sh OUT_DIR [RUNS]   (after scripts/build.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/akimap-benchmark.sh OUT_DIR [RUNS]}
runs=${2:-10}
bin=${DENSEMAP_BUILD_DIR:-build}/bin
mkdir -p "$out"
for scene in structured unstructured; do
  echo "akimap-benchmark: simulating $scene"
  "$bin/densemap-sim" --out "$out/$scene" --scene "$scene" --sensor os0-64 --columns 512 \
    --scans 12 --points-per-scan 3500 --max-range 8 --oracle-factor 2 \
    --oracle-resolutions 0.1,0.05 --gt-resolution 0.05
  for res in 0.1 0.05; do
    echo "akimap-benchmark: $scene at $res m, $runs runs"
    "$bin/densemap-eval" --data "$out/$scene" --protocol oracle --resolution "$res" \
      --max-range 8 --runs "$runs" --json "$out/${scene}_$res.json" \
      --roc "$out/roc_${scene}_$res" --slice "$out/slice_${scene}_$res" --slice-z 1.0 \
      | tee "$out/${scene}_$res.txt"
  done
done
