#!/usr/bin/env bash
# `densemap status --watch` with stdout redirected to a file
# writes each status line at once (it wrote nothing: stdout was buffered), and when the server
# stops it ends with an error within seconds (it repeated the last status forever).
# Usage: status_watch_cli.sh SERVER_BIN CLI_BIN DOMAIN
set -euo pipefail
server=$1 cli=$2 domain=$3
dir=$(mktemp -d)
printf 'dds { domain_id: %s network_interface: "lo" }\nsnapshot { path: "" }\n' "$domain" \
  >"$dir/server.textproto"
"$server" --config "$dir/server.textproto" 2>"$dir/server.log" &
pid=$!
"$cli" --domain-id "$domain" status --watch >"$dir/watch.txt" 2>"$dir/watch.err" &
watch=$!
trap 'kill $pid $watch 2>/dev/null || true; rm -rf "$dir"' EXIT
# Lines reach the file while the watch runs (flushed, not held in a buffer).
for _ in $(seq 100); do
  [ "$(grep -c 'map version' "$dir/watch.txt" || true)" -ge 2 ] && break
  sleep 0.1
done
lines=$(grep -c 'map version' "$dir/watch.txt" || true)
if [ "$lines" -lt 2 ]; then
  echo "status_watch_cli: $lines status lines in the file after 10 s"; exit 1
fi
kill -TERM $pid
wait $pid || true
# The watch ends by itself, with an error, once the server is gone.
for _ in $(seq 150); do kill -0 $watch 2>/dev/null || break; sleep 0.1; done
if kill -0 $watch 2>/dev/null; then
  echo "status_watch_cli: the watch still runs 15 s after the server stopped"; exit 1
fi
rc=0
wait $watch || rc=$?
if [ "$rc" -eq 0 ]; then echo "status_watch_cli: the watch exited 0 after the server stopped"; exit 1; fi
echo "status_watch_cli: $lines lines while the server ran; exit $rc after it stopped: $(tail -1 "$dir/watch.err")"
