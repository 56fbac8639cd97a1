#!/usr/bin/env bash
# The thread-scaling figure with its spread: runs densemap-bench RUNS times on DATA at
# RES / RANGE (grid backend, set rule) with a 1-thread and a 2-thread lane of METHOD, by
# default in the same run as OctoMap, and prints each run's p50 of both lanes and their
# ratio, then the ratios' mean, min and max. One run is not a figure: on a shared VM the ratio
# of the same binary drifts with the host's load.
# Also prints the ratio of the p50s over the scans within the lanes' turns (the bench's turn
# table): the scans that open a turn wake the second thread after the other lanes ran, which
# can cost the 2-thread lane milliseconds.
# Each run's cache probes (the vCPUs' share of the last-level cache before and after its lanes)
# follow its line.
# Fails when a run does not report both lanes or reports a cell differing from OctoMap.
# Usage: scripts/scaling-check.sh [RUNS=3] [DATA=../shared/data/balm-realworld] [RES=0.1]
#        [RANGE=30]
# Environment: DENSEMAP_BIN (default build/bin), METHOD (default raycast), OCTOMAP=0 leaves
# OctoMap's lane out (faster, and then no lane idles the second thread for seconds between
# turns: not the issue's setting), OUT (default a new /tmp/densemap-scaling.XXXXXX) keeps each
# run's table.
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${1:-3} DATA=${2:-../shared/data/balm-realworld} RES=${3:-0.1} RANGE=${4:-30}
BIN=${DENSEMAP_BIN:-build/bin}
METHOD=${METHOD:-raycast}
OUT=${OUT:-$(mktemp -d /tmp/densemap-scaling.XXXXXX)}
mkdir -p "$OUT"
if [ ! -e "$DATA" ]; then
  echo "scaling-check: no data at $DATA (set DATA, or DENSEMAP_DATA_DIR)" >&2
  exit 2
fi
METHODS="$METHOD@t1,$METHOD@t2"
[ "${OCTOMAP:-1}" = 0 ] || METHODS="octomap,$METHODS"
echo "scaling-check: $RUNS runs of densemap-bench --data $DATA --resolution $RES" \
  "--max-range $RANGE --methods $METHODS --backend grid; tables in $OUT"
ratios=() withins=()
for run in $(seq 1 "$RUNS"); do
  "$BIN/densemap-bench" --data "$DATA" --resolution "$RES" --max-range "$RANGE" \
    --methods "$METHODS" --backend grid > "$OUT/run$run.txt" 2> "$OUT/run$run.log"
  # The summary table's rows: method backend rule thr scans points p50 p99 ... diff speedup.
  read -r t1 t2 diff < <(awk -v a="$METHOD@t1" -v b="$METHOD@t2" '
    $2 == "grid" && $3 == "set" && $1 == a { t1 = $7; d += $(NF - 1) }
    $2 == "grid" && $3 == "set" && $1 == b { t2 = $7; d += $(NF - 1) }
    END { printf "%s %s %s\n", (t1 == "" ? "-" : t1), (t2 == "" ? "-" : t2), d + 0 }' \
    "$OUT/run$run.txt")
  if [ "$t1" = - ] || [ "$t2" = - ]; then
    echo "scaling-check: run $run reported no $METHOD@t1 or @t2 lane (see $OUT/run$run.log)" >&2
    exit 1
  fi
  if [ "$diff" != 0 ]; then
    echo "scaling-check: run $run: $diff cells differ from OctoMap" >&2
    exit 1
  fi
  ratio=$(awk -v a="$t1" -v b="$t2" 'BEGIN { printf "%.3f", a / b }')
  ratios+=("$ratio")
  # The turn table's rows: method backend thr openers p50 rest p50 (the rest: the scans that do
  # not open a lane's turn, so no wake-up of the second thread after the other lanes ran).
  read -r w1 w2 < <(awk -v a="$METHOD@t1" -v b="$METHOD@t2" '
    NF == 7 && $2 == "grid" && $3 ~ /^[0-9]+$/ && $1 == a { w1 = $7 }
    NF == 7 && $2 == "grid" && $3 ~ /^[0-9]+$/ && $1 == b { w2 = $7 }
    END { printf "%s %s\n", (w1 == "" ? "-" : w1), (w2 == "" ? "-" : w2) }' "$OUT/run$run.txt")
  within=-
  if [ "$w1" != - ] && [ "$w2" != - ]; then
    within=$(awk -v a="$w1" -v b="$w2" 'BEGIN { printf "%.3f", a / b }')
    withins+=("$within")
  fi
  echo "run $run ($(date +%H:%M)): p50 $t1 ms at 1 thread, $t2 ms at 2; ratio $ratio" \
    "(within turns: $w1 / $w2 ms, $within)"
  sed -n 's/^cache probe /  cache probe /p' "$OUT/run$run.txt"  # the vCPUs' cache share
done
summary() {
  awk -v what="$1" '
    { s += $1; if (NR == 1 || $1 < lo) lo = $1; if (NR == 1 || $1 > hi) hi = $1 }
    END { if (NR) printf "%s over %d runs: mean %.3f, min %.3f, max %.3f\n", what, NR, s / NR, lo, hi }'
}
printf '%s\n' "${ratios[@]}" | summary ratio
[ "${#withins[@]}" = 0 ] || printf '%s\n' "${withins[@]}" | summary "ratio within turns"
