#!/usr/bin/env bash
# `densemap replay` reuses a scan's buffers from its heap: sending a 64-beam scan (about 2 MB)
# takes few new pages once the first scans are sent (on fresh pages, over a thousand minor
# faults a scan: the sender's largest cost, on cores it may share with the server). Reads the
# replay's own report of its faults over the last half of the scans.
# Usage: replay_heap_cli.sh SERVER_BIN CLI_BIN SIM_BIN DOMAIN
set -euo pipefail
server=$1 cli=$2 sim=$3 domain=$4
dir=$(mktemp -d)
pid=
trap '[ -n "$pid" ] && kill $pid 2>/dev/null; rm -rf "$dir"' EXIT
"$sim" --out "$dir/drive" --scene outdoor --sensor hdl64 --scans 16 --gt-resolution 0 >/dev/null 2>&1
printf 'dds { domain_id: %s network_interface: "lo" }\nsnapshot { path: "" }\nmap { resolution_m: 0.4 max_range_m: 40 }\n' \
  "$domain" >"$dir/server.textproto"
"$server" --config "$dir/server.textproto" 2>"$dir/server.log" &
pid=$!
"$cli" --domain-id "$domain" replay --data "$dir/drive" --rate 20 >"$dir/replay.txt" 2>&1 ||
  { cat "$dir/replay.txt"; exit 1; }
line=$(grep "minor page faults over the last" "$dir/replay.txt") ||
  { echo "no fault report in:"; cat "$dir/replay.txt"; exit 1; }
per_scan=$(sed -n 's/.*faults over the last [0-9]* scans (\([0-9.]*\) a scan).*/\1/p' <<<"$line")
echo "$line"
awk -v n="$per_scan" 'BEGIN { exit !(n != "" && n < 300) }' ||
  { echo "replay_heap_cli: $per_scan minor page faults a scan (at most 300)"; exit 1; }
kill -TERM "$pid"; wait "$pid"; pid=
echo "replay_heap_cli: ok"
