#!/usr/bin/env bash
# Users' own recordings: a ROS 2 MCAP bag (densemap-sim --mcap, zstd chunks) replayed
# into the server at its recorded rate gives the map densemap-map makes of the same scans from
# the dataset directory, byte for byte as OctoMap's .bt; densemap-map reads the bag to the same
# map too. One server, loopback only, its own domain.
# Usage: recording_replay_cli.sh SERVER_BIN CLI_BIN MAP_BIN SIM_BIN DOMAIN
set -euo pipefail
server=$1 cli=$2 map=$3 sim=$4 domain=$5
dir=$(mktemp -d)
server_pid=""
cleanup() {
  [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT
"$sim" --out "$dir/data" --sensor vlp16 --scene indoor --columns 600 --scans 8 \
  --gt-resolution 0 --mcap "$dir/run.mcap" --mcap-compression zstd >/dev/null
"$map" --data "$dir/data" --out "$dir/dir.bt" --resolution 0.1 --max-range 20 >/dev/null 2>&1
"$map" --data "$dir/run.mcap" --out "$dir/bag_offline.bt" --resolution 0.1 --max-range 20 \
  >/dev/null 2>&1
cmp "$dir/dir.bt" "$dir/bag_offline.bt" || { echo "densemap-map: the bag's map differs"; exit 1; }
cat >"$dir/server.textproto" <<CFG
map { resolution_m: 0.1 max_range_m: 20 }
snapshot { path: "" autosave_period_s: 0 }
dds { domain_id: $domain network_interface: "lo" }
CFG
"$server" --config "$dir/server.textproto" 2>"$dir/server.log" &
server_pid=$!
"$cli" --domain-id "$domain" replay --data "$dir/run.mcap" --recorded-rate >"$dir/replay.txt" 2>&1 \
  || { echo "replay failed:"; cat "$dir/replay.txt"; exit 1; }
grep -q "server integrated 8, dropped 0, rejected 0" "$dir/replay.txt" \
  || { echo "not every cloud integrated:"; cat "$dir/replay.txt"; exit 1; }
grep -q "8 clouds on /points in frame map" "$dir/replay.txt" \
  || { echo "the bag was not read as 8 posed clouds:"; cat "$dir/replay.txt"; exit 1; }
"$cli" --domain-id "$domain" snapshot --out "$dir/bag.bt" >/dev/null
cmp "$dir/dir.bt" "$dir/bag.bt" || { echo "the server's map of the bag differs"; exit 1; }
# --recorded-rate needs stamps: a dataset directory has none.
if "$cli" --domain-id "$domain" replay --data "$dir/data" --recorded-rate >"$dir/err.txt" 2>&1; then
  echo "--recorded-rate on a directory did not fail"; exit 1
fi
grep -q "needs scans with stamps" "$dir/err.txt" || { cat "$dir/err.txt"; exit 1; }
echo "recording_replay_cli: ok"
