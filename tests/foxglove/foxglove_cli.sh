#!/usr/bin/env bash
# densemap-server's Foxglove WebSocket endpoint, driven by the real client library
# (@foxglove/ws-protocol) under Node: a client connected before the scans and one joining
# after them each rebuild the occupied cells from /densemap/occupied, and both equal the
# server's .dmap snapshot at the same version; every advertised channel decodes. Then the
# hostile cases (hostile.mjs) leave the server running with its map intact, a client that never
# reads is closed once its send stalls (counted in status) while the others go on, and a client
# over wss (TLS, a self-signed certificate) sees the same map.
# Usage: foxglove_cli.sh SERVER CLI SIM DMAP_OCCUPIED DOMAIN PORT
set -euo pipefail
server=$1 cli=$2 sim=$3 occupied=$4 domain=$5 port=$6
here=$(cd "$(dirname "$0")" && pwd)
command -v node >/dev/null || { echo "foxglove_cli: no node (scripts/install-deps.sh installs nodejs)"; exit 1; }
[ -d "$here/node_modules/@foxglove/ws-protocol" ] ||
  { echo "foxglove_cli: no $here/node_modules (scripts/test.sh runs npm ci there)"; exit 1; }
dir=$(mktemp -d)
pid=""
cleanup() {
  [ -n "$pid" ] && kill "$pid" 2>/dev/null || true
  jobs -p | xargs -r kill 2>/dev/null || true
  rm -rf "$dir"
}
trap cleanup EXIT
scans=12
"$sim" --out "$dir/sim" --scene indoor --sensor vlp16 --scans $scans --gt-resolution 0 --threads 2 >/dev/null

start_server() {  # CONFIG_EXTRA
  cat >"$dir/server.textproto" <<EOF
map { resolution_m: 0.2 max_range_m: 30 }
dds { domain_id: $domain network_interface: "lo" }
snapshot { path: "" }
foxglove { enabled: true port: $port grid_period_s: 0.2 max_clients: 8 stall_close_s: 1 $1 }
EOF
  "$server" --config "$dir/server.textproto" 2>>"$dir/server.log" &
  pid=$!
}

integrated() {
  "$cli" --domain-id "$domain" status 2>/dev/null | sed -n 's/.*integrated \([0-9]*\).*/\1/p' | head -1
}

compare() {  # NAME CELLS_FILE
  if ! cmp -s "$dir/snapshot.txt" "$2"; then
    echo "foxglove_cli: $1: the cells differ from the snapshot's ($(wc -l <"$2") vs $(wc -l <"$dir/snapshot.txt"))"
    diff "$dir/snapshot.txt" "$2" | head -10
    exit 1
  fi
  echo "foxglove_cli: $1: $(wc -l <"$2") occupied cells, equal to the snapshot's"
}

# Send queues of 4 MiB: the stalled client below fills its queue (two 128-beam scans) within
# its stall_close_s however slowly a loaded machine integrates the drive.
start_server "max_queue_bytes: 4194304"
url="ws://127.0.0.1:$port"
# The early client: connected and subscribed before any scan.
node "$here/client.mjs" --url "$url" --out "$dir/early.txt" --channels "$dir/channels.json" \
  --version-file "$dir/version" &
early=$!
for _ in $(seq 200); do [ -s "$dir/channels.json" ] && break; sleep 0.1; done
[ -s "$dir/channels.json" ] || { echo "foxglove_cli: the early client saw no channels"; cat "$dir/server.log"; exit 1; }
"$cli" --domain-id "$domain" replay --data "$dir/sim" --rate 20 >/dev/null 2>&1
for _ in $(seq 300); do [ "$(integrated)" = "$scans" ] && break; sleep 0.1; done
[ "$(integrated)" = "$scans" ] || { echo "foxglove_cli: the server integrated $(integrated) of $scans"; exit 1; }
"$cli" --domain-id "$domain" snapshot --out "$dir/map.dmap" >/dev/null
version=$("$occupied" "$dir/map.dmap" "$dir/snapshot.txt")
[ "$(wc -l <"$dir/snapshot.txt")" -gt 1000 ] || { echo "foxglove_cli: a map of too few cells"; exit 1; }
echo "$version" >"$dir/version"
wait "$early"
compare "early client at version $version" "$dir/early.txt"
# The late client joins after every scan: the whole map first.
node "$here/client.mjs" --url "$url" --out "$dir/late.txt" --version-file "$dir/version"
compare "late client" "$dir/late.txt"

# Every channel advertised, with its schema, and each decoded.
node -e '
const fs = require("fs");
const c = JSON.parse(fs.readFileSync(process.argv[1])).channels;
const want = {"/densemap/occupied": "foxglove.SceneUpdate", "/densemap/grid": "nav_msgs/msg/OccupancyGrid",
  "/densemap/scan": "sensor_msgs/msg/PointCloud2", "/tf": "foxglove.FrameTransforms",
  "/densemap/trajectories": "foxglove.SceneUpdate", "/densemap/status": "densemap.Status"};
for (const [topic, schema] of Object.entries(want)) {
  const ch = c.find((x) => x.topic === topic);
  if (!ch || ch.schemaName !== schema || ch.schemaBytes === 0) { console.error("channel " + topic + ": " + JSON.stringify(ch)); process.exit(1); }
}
const s = JSON.parse(fs.readFileSync(process.argv[2]));
for (const topic of Object.keys(want)) if (!(s.messages[topic] > 0)) { console.error("no message on " + topic + ": " + JSON.stringify(s.messages)); process.exit(1); }
if (!(s.scanPoints > 0) || !(s.transformsSeen >= 1) || !s.grid || s.status.integrated !== Number(process.argv[3])) { console.error(JSON.stringify(s)); process.exit(1); }
console.log("foxglove_cli: channels " + c.map((x) => x.topic).join(", ") + ": each decoded");
' "$dir/channels.json" "$dir/early.txt.json" "$scans"

# Hostile clients: the server keeps running, counts them, and its map is intact.
node "$here/hostile.mjs" --url "$url"
kill -0 "$pid" || { echo "foxglove_cli: the server died"; cat "$dir/server.log"; exit 1; }
node "$here/client.mjs" --url "$url" --out "$dir/after.txt" --version-file "$dir/version"
compare "a client after the hostile ones" "$dir/after.txt"
"$cli" --domain-id "$domain" status >"$dir/status.txt"
grep -q "foxglove: .* connections or operations refused" "$dir/status.txt" ||
  { echo "foxglove_cli: no foxglove line in the status"; cat "$dir/status.txt"; exit 1; }
refused=$(sed -n 's/.*stalled queues, \([0-9]*\) connections or operations refused.*/\1/p' "$dir/status.txt")
[ "${refused:-0}" -gt 10 ] || { echo "foxglove_cli: $refused refusals counted"; cat "$dir/status.txt"; exit 1; }
echo "foxglove_cli: hostile clients refused ($refused counted), the map intact"

# A client that never reads, while a 128-beam drive streams (more than the kernel's socket
# buffers hold): its queue fills, its frames are dropped, it is closed and counted; a client
# that reads gets the whole map.
"$sim" --out "$dir/sim128" --scene indoor --sensor os128 --scans 15 --gt-resolution 0 --threads 2 >/dev/null 2>&1
node "$here/client.mjs" --url "$url" --stall --out "$dir/stall.json" &
stall=$!
sleep 1
"$cli" --domain-id "$domain" replay --data "$dir/sim128" --rate 10 >/dev/null 2>&1
for _ in $(seq 300); do [ "$(integrated)" = "$((scans + 15))" ] && break; sleep 0.1; done
sleep 2
"$cli" --domain-id "$domain" status >"$dir/status.txt"
closed=$(sed -n 's/.* \([0-9]*\) clients closed for stalled queues.*/\1/p' "$dir/status.txt")
dropped=$(sed -n 's/.*; \([0-9]*\) frames dropped for full send queues.*/\1/p' "$dir/status.txt")
[ "${closed:-0}" -ge 1 ] && [ "${dropped:-0}" -ge 1 ] ||
  { echo "foxglove_cli: the stalled client: closed $closed, dropped $dropped"; cat "$dir/status.txt"; exit 1; }
kill "$stall" 2>/dev/null || true
"$cli" --domain-id "$domain" snapshot --out "$dir/map3.dmap" >/dev/null
version=$("$occupied" "$dir/map3.dmap" "$dir/snapshot.txt")
echo "$version" >"$dir/version"
node "$here/client.mjs" --url "$url" --out "$dir/after-stall.txt" --version-file "$dir/version"
compare "a stalled client closed ($closed; $dropped frames dropped), then a client" "$dir/after-stall.txt"
kill -TERM "$pid"
wait "$pid"
pid=""

# wss: the same map through TLS (a self-signed certificate for 127.0.0.1, trusted by the client).
if command -v openssl >/dev/null; then
  openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj "/CN=127.0.0.1" \
    -addext "subjectAltName=IP:127.0.0.1" -keyout "$dir/key.pem" -out "$dir/cert.pem" 2>/dev/null
  start_server "certificate_chain: \"$dir/cert.pem\" private_key: \"$dir/key.pem\""
  "$cli" --domain-id "$domain" replay --data "$dir/sim" --rate 20 >/dev/null 2>&1
  for _ in $(seq 300); do [ "$(integrated)" = "$scans" ] && break; sleep 0.1; done
  "$cli" --domain-id "$domain" snapshot --out "$dir/map2.dmap" >/dev/null
  version=$("$occupied" "$dir/map2.dmap" "$dir/snapshot.txt")
  echo "$version" >"$dir/version"
  NODE_EXTRA_CA_CERTS="$dir/cert.pem" node "$here/client.mjs" --url "wss://127.0.0.1:$port" \
    --out "$dir/tls.txt" --version-file "$dir/version"
  compare "a wss client" "$dir/tls.txt"
  kill -TERM "$pid"
  wait "$pid"
  pid=""
fi
echo "foxglove_cli: passed"
