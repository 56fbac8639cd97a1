#!/usr/bin/env bash
# The main job until the server lands (see README): simulate a short outdoor drive, integrate
# it with densemap and with OctoMap in one benchmark run, and export the map for octovis.
# Usage: scripts/demo.sh [output dir, default /tmp/densemap-demo]
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/densemap-demo}
./scripts/install-deps.sh
DENSEMAP_BUILD_TARGETS="densemap-sim densemap-bench densemap-map" ./scripts/build.sh
mkdir -p "$OUT"
echo "== simulating 10 scans of a 64-beam LiDAR driving down a street"
build/bin/densemap-sim --out "$OUT/outdoor" --scene outdoor --sensor hdl64 --scans 10 \
  --noise-std 0.01 --gt-resolution 0.2
echo "== integrating with OctoMap and densemap (0.2 m, 40 m max range), comparing cell by cell"
build/bin/densemap-bench --data "$OUT/outdoor" --resolution 0.2 --max-range 40 \
  --methods octomap,raycast --backend grid,octree --json "$OUT/bench.json"
echo "== exporting the map for OctoMap's tools"
build/bin/densemap-map --data "$OUT/outdoor" --resolution 0.2 --max-range 40 --out "$OUT/map.bt"
echo "demo: outputs in $OUT (dataset, ground_truth.bt, bench.json, map.bt — open with octovis)"
