#!/usr/bin/env bash
# What DDS Security costs on the path a robot takes: the same dataset replayed by `densemap
# replay` to a densemap-server without and with a security block (a fresh make-pki.sh PKI, the
# robot identity), at each rate. Prints one table row per run: scans integrated / dropped, the
# server's latency (receive -> published) and end-to-end latency (publish -> map event seen),
# p50 and p99, and the replay's wall time. Loopback only (run it inside `unshare -n` as
# scripts/test.sh does, or on a machine where lo is all you want).
# Usage: scripts/security-overhead.sh DATASET RATE_HZ [RATE_HZ ...]
#   e.g. build/bin/densemap-sim --out /tmp/hdl --scene outdoor --sensor hdl64 --scans 60 \
#          --gt-resolution 0 && scripts/security-overhead.sh /tmp/hdl 10 20
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 2 ]; then
  echo "usage: $0 DATASET RATE_HZ [RATE_HZ ...]" >&2
  exit 2
fi
data=$(realpath "$1")
shift
BIN=${DENSEMAP_BIN:-build/bin}
if [ -n "${CYCLONEDDS_URI:-}" ]; then
  echo "security-overhead: CYCLONEDDS_URI is set; unset it (this script stays on lo)" >&2
  exit 2
fi
work=$(mktemp -d)
server_pid=""
cleanup() {
  [ -z "$server_pid" ] || kill "$server_pid" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
scripts/make-pki.sh --days 1 "$work/pki" >/dev/null
p="$work/pki"
domain=158
printf 'map { resolution_m: 0.2 }\nsnapshot { path: "" }\ndds { domain_id: %d }\n' "$domain" \
  >"$work/plain.textproto"
{
  cat "$work/plain.textproto"
  printf 'security { identity_ca: "%s" identity_certificate: "%s" private_key: "%s" ' \
    "$p/ca.pem" "$p/server.pem" "$p/server.key"
  printf 'permissions_ca: "%s" governance: "%s" permissions: "%s" }\n' \
    "$p/ca.pem" "$p/governance.p7s" "$p/permissions.p7s"
} >"$work/secure.textproto"

printf '| mode | rate Hz | integrated | dropped | server p50 / p99 ms | end-to-end p50 / p99 ms | wall s |\n'
printf '|---|---|---|---|---|---|---|\n'
for rate in "$@"; do
  for mode in plain secure; do
    auth=()
    [ "$mode" = plain ] || auth=(--pki "$p" --role robot)
    "$BIN/densemap-server" --config "$work/$mode.textproto" >"$work/server.log" 2>&1 &
    server_pid=$!
    sleep 2
    start=$(date +%s.%N)
    "$BIN/densemap" --domain-id "$domain" "${auth[@]}" replay --data "$data" --rate "$rate" \
      >"$work/replay.txt" 2>&1 || { cat "$work/replay.txt" >&2; exit 1; }
    end=$(date +%s.%N)
    kill "$server_pid"
    wait "$server_pid" || true
    server_pid=""
    counts=$(grep -oE 'integrated [0-9]+, dropped [0-9]+' "$work/replay.txt" | tail -1)
    server=$(grep 'server-side latency' "$work/replay.txt" | grep -oE 'p50 [0-9.]+ ms, p99 [0-9.]+' |
      sed -E 's/p50 ([0-9.]+) ms, p99 ([0-9.]+)/\1 \/ \2/')
    e2e=$(grep 'end-to-end latency' "$work/replay.txt" | grep -oE 'p50 [0-9.]+ ms, p99 [0-9.]+' |
      sed -E 's/p50 ([0-9.]+) ms, p99 ([0-9.]+)/\1 \/ \2/')
    printf '| %s | %s | %s | %s | %s | %s | %s |\n' "$mode" "$rate" \
      "$(echo "$counts" | awk '{print $2}' | tr -d ,)" "$(echo "$counts" | awk '{print $4}')" \
      "$server" "$e2e" "$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }')"
  done
done
