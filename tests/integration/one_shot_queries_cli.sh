#!/usr/bin/env bash
# One-shot `densemap query point` runs, each a new DDS participant, against one server: every
# run must get its reply, so a reply must wait until the server's reply writer has matched the
# new client's reply reader. Fails on any failed run.
# Usage: one_shot_queries_cli.sh SERVER_BIN CLI_BIN RUNS DOMAIN
set -euo pipefail
server=$1 cli=$2 runs=$3 domain=$4
dir=$(mktemp -d)
printf 'dds { domain_id: %s network_interface: "lo" }\nsnapshot { path: "" }\n' "$domain" \
  >"$dir/server.textproto"
"$server" --config "$dir/server.textproto" 2>"$dir/server.log" &
pid=$!
trap 'kill $pid 2>/dev/null || true; rm -rf "$dir"' EXIT
failed=0
for i in $(seq "$runs"); do
  if ! "$cli" --domain-id "$domain" query point 1 1 1 >"$dir/out.txt" 2>&1; then
    failed=$((failed + 1))
    echo "run $i failed: $(cat "$dir/out.txt")"
  fi
done
kill -TERM $pid
wait $pid
echo "one_shot_queries_cli: $runs runs, $failed failed"
[ "$failed" -eq 0 ]
