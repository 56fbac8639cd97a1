#!/usr/bin/env bash
# The main job, one command: install, build, simulate a short outdoor drive, run
# densemap-server on loopback, replay the scans at 10 Hz, query the map, save .dmap and .bt
# snapshots and a picture, stop the server cleanly, print a summary.
# Usage: scripts/demo.sh [--ros] [output dir, default /tmp/densemap-demo]
#   --ros: the scans go in as a ROS 2 robot sends them (sensor_msgs/PointCloud2 on rt/points,
#   TF on rt/tf and rt/tf_static; densemap replay --ros) and the server also publishes
#   octomap_binary, projected_map and octomap_point_cloud_centers (docs/ros2.md).
set -euo pipefail
cd "$(dirname "$0")/.."
ROS=0
if [ "${1:-}" = "--ros" ]; then
  ROS=1
  shift
fi
OUT=${1:-/tmp/densemap-demo}
DOMAIN=${DENSEMAP_DEMO_DOMAIN:-57}
./scripts/install-deps.sh
DENSEMAP_BUILD_TARGETS="densemap-sim densemap-server densemap densemap-bench" ./scripts/build.sh
BIN=build/bin
rm -rf "$OUT" && mkdir -p "$OUT"

echo "== 1. simulating 20 scans of a 64-beam LiDAR driving down a street"
$BIN/densemap-sim --out "$OUT/outdoor" --scene outdoor --sensor hdl64 --scans 20 \
  --noise-std 0.01 --gt-resolution 0.2

echo "== 2. starting densemap-server on loopback (DDS domain $DOMAIN)"
cat > "$OUT/server.textproto" <<CFG
map { backend: "grid" resolution_m: 0.2 max_range_m: 40 }
pipeline { threads: 2 queue_depth: 2 }
snapshot { path: "$OUT/server.dmap" autosave_period_s: 0 }
dds { domain_id: $DOMAIN network_interface: "lo" }
CFG
REPLAY_ROS=()
if [ "$ROS" -eq 1 ]; then
  echo 'ros2 { enabled: true reliable_clouds: true publish_period_s: 1 }' >> "$OUT/server.textproto"
  REPLAY_ROS=(--ros)
fi
$BIN/densemap-server --config "$OUT/server.textproto" 2> "$OUT/server.log" &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true' EXIT
CLI="$BIN/densemap --domain-id $DOMAIN"

echo "== 3. replaying the scans at 10 Hz${REPLAY_ROS:+ as ROS 2 PointCloud2 + TF}"
$CLI replay --data "$OUT/outdoor" --rate 10 "${REPLAY_ROS[@]}" | tee "$OUT/replay.txt"

echo "== 4. queries"
$CLI query point 20 -1.5 1.8 20 12 3 60 -4.6 1.0
$CLI query ray --origin 20 -1.5 1.8 --direction 0 1 0 --range 40
$CLI query bbox --min 0 -8 0 --max 40 8 3
$CLI status

echo "== 5. snapshots and a picture"
$CLI snapshot --out "$OUT/map.dmap"
$CLI snapshot --out "$OUT/map.bt"
$CLI render --in "$OUT/map.dmap" --out "$OUT/map.png"

echo "== 6. stopping the server (SIGTERM: finish, save, exit 0)"
kill -TERM $SERVER
wait $SERVER
trap - EXIT
cat "$OUT/server.log"

echo
echo "== summary"
grep -E "^replay: (server integrated|end-to-end)" "$OUT/replay.txt" || true
ls -l "$OUT/map.dmap" "$OUT/map.bt" "$OUT/map.png" "$OUT/server.dmap" "$OUT/outdoor/ground_truth.bt" \
  | awk '{print "  " $NF " (" $5 " bytes)"}'
echo "demo: done; open $OUT/map.png, or $OUT/map.bt with octovis"
