#!/usr/bin/env bash
# Prints docs/benchmarks.md's planner tables, measured now on this machine: the distance
# field's update per scan against the integration of the same scan (densemap-bench --esdf, the
# field a stage of its own in the same run), its memory against the map's, and the planner
# queries on the final map beside the same questions asked as box queries.
# Usage: scripts/planner-benchmark.sh [DATA]
#   DATA: default $DENSEMAP_DATA_DIR/balm-realworld (DENSEMAP_DATA_DIR defaults to
#   ../shared/data); also a simulated 64-beam drive (densemap-sim --sensor hdl64 --scene
#   outdoor) at 0.2 m / 80 m.
# Environment: DENSEMAP_BIN (default build/bin), THREADS (default 2), RUNS (default 3),
#   MAX_DISTANCE (default 2.0 m), SIM_SCANS (default 40).
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=${1:-${DENSEMAP_DATA_DIR:-../shared/data}/balm-realworld}
BIN=${DENSEMAP_BIN:-build/bin}
THREADS=${THREADS:-2}
RUNS=${RUNS:-3}
MAX_DISTANCE=${MAX_DISTANCE:-2.0}
SIM_SCANS=${SIM_SCANS:-40}
for b in densemap-bench densemap-sim; do
  [ -x "$BIN/$b" ] || { echo "planner-benchmark: $BIN/$b is missing: run scripts/build.sh" >&2; exit 2; }
done
OUT=$(mktemp -d /tmp/densemap-planner.XXXXXX)
trap 'rm -rf "$OUT"' EXIT
echo "planner-benchmark: simulating $SIM_SCANS hdl64 scans ..." >&2
"$BIN/densemap-sim" --out "$OUT/hdl64" --scene outdoor --sensor hdl64 --scans "$SIM_SCANS" \
  --gt-resolution 0 >/dev/null 2>&1
cpu=$(awk -F': ' '/model name/ {print $2; exit}' /proc/cpuinfo)
echo "Machine: $cpu, $(nproc) vCPUs; $(date -u +%Y-%m-%d); commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown); $THREADS threads, grid backend, raycast, max distance $MAX_DISTANCE m"
echo

# name data resolution max-range: RUNS bench runs, their distance-field rows and the last
# run's planner-query table.
cases=()
[ -d "$DATA" ] && cases+=("BALM|$DATA|0.2|30" "BALM|$DATA|0.1|30") ||
  echo "planner-benchmark: no dataset at $DATA: BALM rows skipped" >&2
cases+=("hdl64 sim|$OUT/hdl64|0.2|80")
echo "| data | resolution | field update p50 / p99 ms | integration p50 ms | field / integration (p50) | class changes / scan | field MiB | map MiB |"
echo "|---|---|---|---|---|---|---|---|"
queries=""
for c in "${cases[@]}"; do
  IFS='|' read -r name dir res range <<<"$c"
  for run in $(seq 1 "$RUNS"); do
    echo "planner-benchmark: $name at $res m, run $run/$RUNS ..." >&2
    "$BIN/densemap-bench" --data "$dir" --resolution "$res" --max-range "$range" \
      --methods raycast --backend grid --threads "$THREADS" --esdf "$MAX_DISTANCE" \
      --cache-probe-mib 0 >"$OUT/run.txt" 2>"$OUT/run.log"
    awk -v name="$name" -v res="$res" '
      /^distance field/ { on = 1; next }
      on && /^raycast/ { printf "| %s | %s m | %s / %s | %s | %sx | %s | %s | %s |\n", name, res, $4, $5, $6, $7, $8, $9, $10; on = 0 }
    ' "$OUT/run.txt"
    if [ "$run" = "$RUNS" ] && [ "$res" = 0.2 ]; then
      queries+=$'\n'"$name at $res m (last run):"$'\n'"$(sed -n '/planner query (final map)/,/within/p' "$OUT/run.txt")"$'\n'
    fi
  done
done
echo
echo "Planner queries on the final map (densemap-bench --esdf), p50 / p99 ms a query:"
echo '```'
printf '%s' "$queries"
echo '```'
