#!/usr/bin/env bash
# Server against core, same scans, same session: runs densemap-server on
# loopback at RES / RANGE, replays DATA at RATE Hz (optionally with point queries), stops it,
# then runs densemap-bench on the same scans with the same method (METHOD, default raycast, the
# server's default; grid, THREADS threads). Prints the server's latency p50/p99, drops, RSS, the
# replay client's CPU (it runs on the same cores), and the bench's p50/p99.
# Writes $OUT/scans.csv (densemap replay --csv: per-scan latency and map size) and rss.txt.
# Usage: scripts/realtime-check.sh DATA RES RANGE [RATE=10] [FIRST=0] [LIMIT=0] [QUERY_POINTS=0]
# Environment: DENSEMAP_BIN (default build/bin), DENSEMAP_DOMAIN (default 77), BENCH=0 skips the
# bench, BBOX_EDGE=M adds a client sending M-metre bbox queries back to back, SNAPSHOT=1 times a
# late joiner's fetch of the whole map, PERF=1 records `perf record -g` of the server into
# $OUT/perf.data, WARM_UP=true turns the pipeline's warm-up on, HEAP_KEEP_MB=N sets
# pipeline.heap_keep_mb, LEGACY=1 drives a densemap
# built before replay's --csv and --query-bbox-edge (before/after runs), KIND=K the server's
# map.kind (default log_odds; a dense kind such as akimap_rays is benched as that kind),
# METHOD=M the server's pipeline.integration (raycast, culling, superray, superray+culling),
# THREADS=N the server's pipeline.threads and the bench's --threads (default 2), ESDF=M the
# server's distance field on (esdf.max_distance_m M; the bench keeps one too, --esdf M),
# FOXGLOVE=N the server's Foxglove endpoint on (port FOXGLOVE_PORT, default 18766) with N
# Node clients subscribed to every channel from before the replay (tests/foxglove/client.mjs
# --follow; the last one --stall, a client that never reads; at nice 19, as viewers on other
# machines would not take the server's cores), their counts in $OUT/foxglove-*.json.
set -euo pipefail
cd "$(dirname "$0")/.."
DATA=$1 RES=$2 RANGE=$3 RATE=${4:-10} FIRST=${5:-0} LIMIT=${6:-0} QUERY=${7:-0}
THREADS=${THREADS:-2}
BIN=${DENSEMAP_BIN:-build/bin}
DOMAIN=${DENSEMAP_DOMAIN:-77}
OUT=$(mktemp -d /tmp/densemap-rt.XXXXXX)
cat > "$OUT/server.textproto" <<CFG
map { backend: "grid" kind: "${KIND:-log_odds}" resolution_m: $RES max_range_m: $RANGE }
pipeline { threads: $THREADS queue_depth: 2 integration: "${METHOD:-raycast}" max_abs_position_m: 10000
           ${WARM_UP:+warm_up: $WARM_UP} ${HEAP_KEEP_MB:+heap_keep_mb: $HEAP_KEEP_MB} }
snapshot { path: "" autosave_period_s: 0 }
dds { domain_id: $DOMAIN network_interface: "lo" }
${ESDF:+esdf { enabled: true max_distance_m: $ESDF \}}
CFG
FOXGLOVE=${FOXGLOVE:-0}
FOXGLOVE_PORT=${FOXGLOVE_PORT:-18766}
if [ "$FOXGLOVE" -gt 0 ]; then
  echo "foxglove { enabled: true port: $FOXGLOVE_PORT }" >> "$OUT/server.textproto"
fi
"$BIN/densemap-server" --config "$OUT/server.textproto" 2> "$OUT/server.log" &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true' EXIT
if [ "${PERF:-0}" = 1 ]; then
  perf record -g -o "$OUT/perf.data" -p $SERVER 2> "$OUT/perf.log" &
  PERF_PID=$!
fi
# RSS of the server (KiB), sampled every 0.5 s while the replay runs.
( while kill -0 $SERVER 2>/dev/null; do
    awk '/VmRSS/ {print $2}' /proc/$SERVER/status 2>/dev/null || true; sleep 0.5
  done > "$OUT/rss.txt" ) &
# The machine's CPU ticks (all, stolen) from /proc/stat's cpu line, for the replay's steal
# share (densemap-bench prints its own: tools/bench/cpu_steal.hpp).
cpu_ticks() { awk '/^cpu / {t = 0; for (i = 2; i <= 9; ++i) t += $i; print t, $9; exit}' /proc/stat; }
CLIENTS=()
for i in $(seq "$FOXGLOVE"); do
  mode=--follow
  [ "$i" = "$FOXGLOVE" ] && mode=--stall
  nice -n 19 node tests/foxglove/client.mjs --url "ws://127.0.0.1:$FOXGLOVE_PORT" $mode \
    --out "$OUT/foxglove-$i.json" 2> "$OUT/foxglove-$i.log" &
  CLIENTS+=($!)
done
[ "$FOXGLOVE" -gt 0 ] && sleep 2  # connected and subscribed before the first scan
read -r ticks0 steal0 < <(cpu_ticks)
extra=(--query-bbox-edge "${BBOX_EDGE:-0}" --csv "$OUT/scans.csv")
[ "${LEGACY:-0}" = 1 ] && extra=()  # a densemap from before these options (A/B runs)
# The replay's CPU (user and system s, bash's `time`), as it shares the server's cores.
TIMEFORMAT='%U %S'
{ time "$BIN/densemap" --domain-id "$DOMAIN" replay --data "$DATA" --rate "$RATE" --first "$FIRST" \
  --limit "$LIMIT" --query-points "$QUERY" "${extra[@]}" 2> "$OUT/replay.log" \
  | tee "$OUT/replay.txt"; } 2> "$OUT/replay-cpu.txt"
awk '{printf "replay client CPU s: %.2f\n", $1 + $2}' "$OUT/replay-cpu.txt" | tee -a "$OUT/replay.txt"
read -r ticks1 steal1 < <(cpu_ticks)
awk -v t="$((ticks1 - ticks0))" -v s="$((steal1 - steal0))" 'BEGIN {
  share = t > 0 ? 100 * s / t : 0
  printf "CPU steal during the replay: %.1f%% of the machine'"'"'s CPU time\n", share
  if (share > 5) print "warning: over 5% stolen by the hypervisor: these times are not comparable with a quieter run'"'"'s"
}' | tee -a "$OUT/replay.txt"
"$BIN/densemap" --domain-id "$DOMAIN" status | tee -a "$OUT/replay.txt"
if [ "${SNAPSHOT:-0}" = 1 ]; then  # a late joiner fetches the whole map
  start=$(date +%s.%N)
  "$BIN/densemap" --domain-id "$DOMAIN" snapshot --out "$OUT/map.dmap" | tee -a "$OUT/replay.txt"
  echo "late-joiner fetch took $(echo "$(date +%s.%N) - $start" | bc) s"
fi
for c in "${CLIENTS[@]}"; do kill -TERM "$c" 2>/dev/null || true; done
for c in "${CLIENTS[@]}"; do wait "$c" 2>/dev/null || true; done
[ -n "${PERF_PID:-}" ] && kill -INT "$PERF_PID" && wait "$PERF_PID" || true
# The kernel's high-water mark: the true peak, not just the 0.5 s samples' largest.
HWM=$(awk '/VmHWM/ {print $2}' /proc/$SERVER/status 2>/dev/null || echo 0)
echo "server minor page faults: $(awk '{print $10}' /proc/$SERVER/stat), CPU s: $(awk '{printf "%.1f", ($14 + $15) / 100}' /proc/$SERVER/stat)"
kill -TERM $SERVER; wait $SERVER || true
trap - EXIT
echo "server peak RSS: $(sort -n "$OUT/rss.txt" | tail -1) KiB (sampled), high-water mark $HWM KiB"
if [ "${BENCH:-1}" = 1 ]; then
  method=${METHOD:-raycast}
  [ "${KIND:-log_odds}" != log_odds ] && method=$KIND
  "$BIN/densemap-bench" --data "$DATA" --resolution "$RES" --max-range "$RANGE" \
    --methods "$method" --backend grid --threads "$THREADS" --first "$FIRST" --limit "$LIMIT" \
    ${ESDF:+--esdf "$ESDF"} 2> "$OUT/bench.log" | tee "$OUT/bench.txt" | head -3
fi
echo "outputs in $OUT"
