#!/usr/bin/env bash
# The foreign-vendor test: a Fast DDS robot (PointCloud2 + TF) and a late Fast DDS viewer
# (/octomap_binary, /projected_map) against densemap-server, in each mode a ROS user may run:
# UDP alone or with Fast DDS's shared memory beside it, clouds best effort or reliable. Each
# mode: a fresh server (ROS face on, loopback, its own domain); every cloud integrated; the
# octomap the viewer decoded with OctoMap equals the server's snapshot cell for cell; the
# grid's occupied and free columns are those of the map. Then a robot started before the server.
# Usage: fastdds_peer_cli.sh SERVER_BIN CLI_BIN SIM_BIN PEER_BIN DOMAIN
set -euo pipefail
server=$1 cli=$2 sim=$3 peer=$4 domain=$5
dir=$(mktemp -d)
server_pid=""
cleanup() {
  [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT
"$sim" --out "$dir/data" --sensor vlp16 --scene indoor --columns 600 --scans 6 \
  --gt-resolution 0 >/dev/null
cat >"$dir/server.textproto" <<CFG
map { resolution_m: 0.1 max_range_m: 20 }
snapshot { path: "" autosave_period_s: 0 }
dds { domain_id: $domain network_interface: "lo" }
ros2 { enabled: true publish_period_s: 0.2 }
CFG
for transport in udp udp+shm; do
  for clouds in best_effort reliable; do
    mode="$transport, $clouds clouds"
    out="$dir/$transport-$clouds"
    mkdir -p "$out"
    "$server" --config "$dir/server.textproto" 2>"$out/server.log" &
    server_pid=$!
    if ! "$peer" "$domain" "$dir/data" 6 "$transport" "$clouds" "$out" >"$out/peer.txt" 2>&1; then
      echo "$mode: the Fast DDS peer failed:"; cat "$out/peer.txt"; exit 1
    fi
    "$cli" --domain-id "$domain" status >"$out/status.txt"
    grep -q "integrated 6, dropped 0, rejected 0" "$out/status.txt" \
      || { echo "$mode: not every cloud integrated:"; cat "$out/status.txt"; exit 1; }
    "$cli" --domain-id "$domain" snapshot --out "$out/server.bt" >/dev/null
    kill "$server_pid"; wait "$server_pid" || true; server_pid=""
    if ! "$peer" --compare "$out/server.bt" "$out/viewer.bt" "$out/grid.txt" >"$out/compare.txt" 2>&1; then
      echo "$mode: the viewer's maps differ from the server's:"; cat "$out/compare.txt"; exit 1
    fi
    echo "$mode: $(grep '^viewer:' "$out/peer.txt"); $(grep 'differing' "$out/compare.txt")"
  done
done
# A robot started first: its /tf_static is written before the server joins;
# Fast DDS answers a late reader's request for it only at its next heartbeat (3 s), and the
# clouds wait for it (ros2.tf_wait_s, 5 s): none may be lost.
out="$dir/robot-first"
mkdir -p "$out"
"$peer" "$domain" "$dir/data" 6 udp best_effort "$out" early >"$out/peer.txt" 2>&1 &
peer_pid=$!
sleep 1
"$server" --config "$dir/server.textproto" 2>"$out/server.log" &
server_pid=$!
wait "$peer_pid" || { echo "robot first: the Fast DDS peer failed:"; cat "$out/peer.txt"; exit 1; }
"$cli" --domain-id "$domain" status >"$out/status.txt"
grep -q "integrated 6, dropped 0, rejected 0" "$out/status.txt" \
  || { echo "robot first: not every cloud integrated:"; cat "$out/status.txt"; exit 1; }
echo "robot first: $(head -1 "$out/status.txt")"
echo "fastdds_peer_cli: ok"
