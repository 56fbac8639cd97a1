#!/usr/bin/env bash
# Prints the tables of docs/benchmarks.md, measured now on this machine, with the machine and
# the date. Each table is one densemap-bench run (every method on the same scans, taking turns)
# or one scripts/realtime-check.sh run; ratios are against OctoMap in the same run.
# Usage: scripts/benchmarks.sh [integration|server|all] [DATA]
#   DATA: a dataset directory, default $DENSEMAP_DATA_DIR/balm-realworld
#   (DENSEMAP_DATA_DIR defaults to ../shared/data).
# Environment: DENSEMAP_BIN (default build/bin), THREADS (default 2),
#   RESOLUTIONS (default "0.1 0.2 0.4"), RANGE (default 30), METHODS (default
#   octomap,raycast,superray+culling).
set -euo pipefail
cd "$(dirname "$0")/.."
WHAT=${1:-all}
DATA=${2:-${DENSEMAP_DATA_DIR:-../shared/data}/balm-realworld}
BIN=${DENSEMAP_BIN:-build/bin}
THREADS=${THREADS:-2}
RANGE=${RANGE:-30}
RESOLUTIONS=${RESOLUTIONS:-0.1 0.2 0.4}
METHODS=${METHODS:-octomap,raycast,superray+culling}
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3
case "$WHAT" in integration|server|all) ;; *) echo "usage: $0 [integration|server|all] [DATA]" >&2; exit 2 ;; esac
if [ ! -d "$DATA" ]; then
  echo "benchmarks: no dataset at $DATA (give DATA, or set DENSEMAP_DATA_DIR)" >&2
  exit 2
fi
for b in densemap-bench densemap-server densemap; do
  [ -x "$BIN/$b" ] || { echo "benchmarks: $BIN/$b is missing: run scripts/build.sh" >&2; exit 2; }
done
OUT=$(mktemp -d /tmp/densemap-benchmarks.XXXXXX)
cpu=$(awk -F': ' '/model name/ {print $2; exit}' /proc/cpuinfo)
echo "Machine: $cpu, $(nproc) vCPUs, $(awk '/MemTotal/ {printf "%.0f GiB", $2 / 1048576}' /proc/meminfo); $(date -u +%Y-%m-%d); commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
echo "Data: $(basename "$DATA") ($(ls "$DATA"/scans 2>/dev/null | wc -l) scans), max range $RANGE m, $THREADS threads, grid backend"
echo

if [ "$WHAT" != server ]; then
  echo "### Integration against OctoMap"
  echo
  echo "scripts/benchmarks.sh integration: densemap-bench --methods $METHODS, per resolution; p50 / p99 ms a scan; speed-up = OctoMap's p50 / the method's, same run; differing = cells differing from OctoMap's map."
  echo
  for res in $RESOLUTIONS; do
    echo "benchmarks: densemap-bench at $res m ..." >&2
    "$BIN/densemap-bench" --data "$DATA" --resolution "$res" --max-range "$RANGE" \
      --methods "$METHODS" --backend grid --threads "$THREADS" --json "$OUT/bench-$res.json" \
      > "$OUT/bench-$res.txt" 2> "$OUT/bench-$res.log"
  done
  "$PY" - "$OUT" $RESOLUTIONS <<'PY'
import json, sys
out, resolutions = sys.argv[1], sys.argv[2:]
rows = [json.load(open(f"{out}/bench-{r}.json"))["runs"] for r in resolutions]
methods = [r["method"] for r in rows[0]]
print("| resolution | " + " | ".join(methods) + " |")
print("|---" * (len(methods) + 1) + "|")
for res, runs in zip(resolutions, rows):
    cells = []
    for r in runs:
        cell = f"{r['ms_per_scan_p50']:.1f} / {r['ms_per_scan_p99']:.1f}"
        if r["method"] != "octomap":
            cell += f" ({r['speedup_vs_octomap']:.1f}x, differing {r['diff_cells_vs_octomap']})"
        cells.append(cell)
    print(f"| {res} m | " + " | ".join(cells) + " |")
PY
  echo
fi

if [ "$WHAT" != integration ]; then
  echo "### The server at 10 Hz against its own engine"
  echo
  echo "scripts/benchmarks.sh server: scripts/realtime-check.sh DATA 0.2 $RANGE 10 (the server on loopback, the replay client on the same cores, then densemap-bench on the same scans)."
  echo
  echo "| map | scans integrated | dropped | server p50 / p99 ms | bench p50 / p99 ms | server peak RSS |"
  echo "|---|---|---|---|---|---|"
  for kind in log_odds akimap_rays; do
    echo "benchmarks: realtime-check.sh, $kind ..." >&2
    KIND=$kind THREADS=$THREADS DENSEMAP_BIN=$BIN DENSEMAP_DOMAIN=${DENSEMAP_DOMAIN:-79} \
      ./scripts/realtime-check.sh "$DATA" 0.2 "$RANGE" 10 > "$OUT/rt-$kind.txt" 2>&1
    "$PY" - "$OUT/rt-$kind.txt" "$kind" <<'PY'
import re, sys
text, kind = open(sys.argv[1]).read(), sys.argv[2]
counts = re.search(r"server integrated (\d+), dropped (\d+)", text)
server = re.search(r"server-side latency \(receive -> published\) p50 ([\d.]+) ms, p99 ([\d.]+) ms", text)
rss = re.search(r"high-water mark (\d+) KiB", text)
bench = None
for line in text.splitlines():
    parts = line.split()
    if len(parts) > 8 and parts[0] in (kind, "raycast"):
        nums = [p for p in parts if re.fullmatch(r"[\d.]+", p)]
        bench = nums
if not (counts and server and rss):
    sys.exit(f"benchmarks: realtime-check's output for {kind} lacks its summary: {sys.argv[1]}")
b = "-"
if bench and len(bench) >= 5:
    # densemap-bench's table: thr, scans, points, p50 ms, p99 ms, ...
    b = f"{float(bench[3]):.1f} / {float(bench[4]):.1f}"
print(f"| {kind} | {counts.group(1)} | {counts.group(2)} | {float(server.group(1)):.1f} / "
      f"{float(server.group(2)):.1f} | {b} | {int(rss.group(1)) // 1024} MiB |")
PY
  done
  echo
fi
echo "benchmarks: outputs in $OUT" >&2
