#!/usr/bin/env bash
# Soak test: a densemap-server on loopback under config/load/soak.textproto for MINUTES minutes
# (a robot replaying a drive in a loop, two viewers, a late joiner every 30 s). Every 10 s the
# load tool records latency, throughput, drops, server CPU and RSS, and this script records the
# server's RSS and its autosaved snapshot's size (soak-samples.csv). Fails (exit 3) when the
# server's RSS grows more than 10% after warm-up, the end-to-end p99 drifts more than 20%, or the
# scenario's SLO breaks (a scan dropped, e2e p99 over 200 ms);
# fails (exit 1) when the server dies, does not stop cleanly or leaves no snapshot.
# Usage: scripts/soak.sh [MINUTES]   (default 2; env DENSEMAP_BIN, DENSEMAP_DOMAIN, SOAK_OUT)
set -euo pipefail
cd "$(dirname "$0")/.."
minutes=${1:-2}
if ! [[ "$minutes" =~ ^[0-9]+$ ]] || [ "$minutes" -lt 1 ] || [ "$minutes" -gt 1440 ]; then
  echo "soak.sh: MINUTES must be a whole number in 1 .. 1440" >&2
  exit 2
fi
bin=${DENSEMAP_BIN:-build/bin}
domain=${DENSEMAP_DOMAIN:-91}
out=${SOAK_OUT:-/tmp/densemap-soak}
for b in densemap densemap-server; do
  [ -x "$bin/$b" ] || { echo "soak.sh: $bin/$b not built (scripts/build.sh)" >&2; exit 2; }
done
rm -rf "$out"
mkdir -p "$out"
cat > "$out/server.textproto" <<CONF
dds { domain_id: $domain network_interface: "lo" }
snapshot { path: "$out/map.dmap" autosave_period_s: 20 }
CONF
"$bin/densemap-server" --config "$out/server.textproto" > "$out/server.log" 2>&1 &
server=$!
sampler=""
cleanup() {
  [ -n "$sampler" ] && kill "$sampler" 2>/dev/null || true
  kill "$server" 2>/dev/null || true
}
trap cleanup EXIT
# Samples every 10 s for as long as the run lasts (bounded by its duration plus 5 minutes).
(
  echo "t_s,server_rss_kib,snapshot_bytes" > "$out/soak-samples.csv"
  start=$(date +%s)
  while [ $(( $(date +%s) - start )) -le $(( minutes * 60 + 300 )) ] && kill -0 "$server" 2>/dev/null; do
    rss=$(awk '/^VmRSS:/ {print $2}' "/proc/$server/status" 2>/dev/null || echo 0)
    snap=$(stat -c %s "$out/map.dmap" 2>/dev/null || echo 0)
    echo "$(( $(date +%s) - start )),$rss,$snap" >> "$out/soak-samples.csv"
    sleep 10
  done
) &
sampler=$!
set +e
"$bin/densemap" --domain-id "$domain" load --scenario config/load/soak.textproto \
  --duration $(( minutes * 60 )) --out "$out"
code=$?
set -e
kill "$sampler" 2>/dev/null || true
sampler=""
if ! kill -0 "$server" 2>/dev/null; then
  echo "soak.sh: FAILED: the server died during the soak (log: $out/server.log)" >&2
  exit 1
fi
kill -TERM "$server"
server_code=0
wait "$server" || server_code=$?
trap - EXIT
echo "soak.sh: server RSS and snapshot size every 10 s ($out/soak-samples.csv):"
column -s, -t < "$out/soak-samples.csv" | awk 'NR == 1 || NR % 6 == 2'
if [ "$server_code" -ne 0 ]; then
  echo "soak.sh: FAILED: the server exited with $server_code on SIGTERM" >&2
  exit 1
fi
if [ ! -s "$out/map.dmap" ]; then
  echo "soak.sh: FAILED: no snapshot at $out/map.dmap" >&2
  exit 1
fi
if [ "$code" -ne 0 ]; then
  echo "soak.sh: FAILED (exit $code): see $out/report.md" >&2
  exit "$code"
fi
echo "soak.sh: passed ($minutes min; report $out/report.md, plot $out/load.png)"
