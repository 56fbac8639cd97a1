#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz) with clang and AddressSanitizer into build-fuzz/ and
# runs each for SECONDS on its seeds (tests/fuzz/corpus/<target> and files made here); new inputs go to
# build-fuzz/corpus/<target>, never into the repository. Fails on any crash, leak or timeout,
# leaving the input in build-fuzz/artifacts/.
# Usage: scripts/fuzz.sh [SECONDS per target, default 10] [TARGET ...]
#   scripts/test.sh runs `scripts/fuzz.sh 10`; a longer run: scripts/fuzz.sh 3600 fuzz_snapshot
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_PER=${1:-10}
shift || true
BUILD=${DENSEMAP_FUZZ_BUILD_DIR:-build-fuzz}
ALL=(fuzz_snapshot fuzz_scan_graph fuzz_scan_dat fuzz_pcd fuzz_dataset fuzz_config fuzz_iln_weights
  fuzz_scan_validation fuzz_point_cloud2 fuzz_queries fuzz_planner_queries fuzz_mcap fuzz_db3 fuzz_ros_names
  fuzz_point_array fuzz_foxglove_ops fuzz_scan_record)
TARGETS=("$@")
[ ${#TARGETS[@]} -gt 0 ] || TARGETS=("${ALL[@]}")
# Debian 12's clang 16 with libstdc++ 12: <expected> wants __cpp_concepts >= 202002, which clang
# 16 implements (P0848) but does not announce.
CXXFLAGS_FUZZ="-U__cpp_concepts -D__cpp_concepts=202002L -fsanitize=fuzzer-no-link,address"
launcher=()
if command -v ccache >/dev/null 2>&1; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-true}
fi
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang-16 -DCMAKE_CXX_COMPILER=clang++-16 "${launcher[@]}" \
  -DDENSEMAP_FUZZ=ON -DDENSEMAP_BUILD_TESTS=OFF -DDENSEMAP_BUILD_TOOLS=OFF -DDENSEMAP_BUILD_PYTHON=OFF \
  "-DCMAKE_CXX_FLAGS=$CXXFLAGS_FUZZ" "-DCMAKE_C_FLAGS=-fsanitize=fuzzer-no-link,address" >/dev/null
build_args=()
for t in "${TARGETS[@]}"; do build_args+=(--target "$t"); done
cmake --build "$BUILD" --parallel "$(nproc)" "${build_args[@]}" >"$BUILD/fuzz-build.log" 2>&1 || {
  tail -30 "$BUILD/fuzz-build.log" >&2
  echo "fuzz.sh: build failed" >&2
  exit 1
}
# Seeds: the committed ones (tests/fuzz/corpus: hand-written syntax cases), plus files made
# here rather than kept in the repository: PCDs written below, the shipped config and ILN
# model, and a .graph of densemap-sim scans (with the main build's tools, when built).
SEEDS="$BUILD/seeds"
rm -rf "$SEEDS"
for t in "${ALL[@]}"; do
  mkdir -p "$SEEDS/$t"
  if [ -d "tests/fuzz/corpus/$t" ]; then cp tests/fuzz/corpus/"$t"/* "$SEEDS/$t/" 2>/dev/null || true; fi
done
pcd_header() {  # DATA_KIND
  printf '# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n'
  printf 'COUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 1 0 0 1 0 0 0\nPOINTS 2\nDATA %s\n' "$1"
}
{ pcd_header ascii; printf '1 2 3 0.5\n4 5 6 0.7\n'; } >"$SEEDS/fuzz_pcd/ascii.pcd"
{ pcd_header binary; printf '\x00\x00\x80\x3f\x00\x00\x00\x40\x00\x00\x40\x40\x00\x00\x00\x3f'
  printf '\x00\x00\x80\x40\x00\x00\xa0\x40\x00\x00\xc0\x40\x33\x33\x33\x3f'; } \
  >"$SEEDS/fuzz_pcd/binary.pcd"
cp config/densemap.textproto "$SEEDS/fuzz_config/shipped.textproto"
cp models/iln.pb "$SEEDS/fuzz_iln_weights/iln.pb"
TOOLS=${DENSEMAP_BIN:-build/bin}
if [ -x "$TOOLS/densemap-sim" ] && [ -x "$TOOLS/densemap-map" ]; then
  "$TOOLS/densemap-sim" --out "$BUILD/seed-sim" --scene indoor --sensor vlp16 --columns 40 \
    --scans 2 --gt-resolution 0 >/dev/null 2>&1
  "$TOOLS/densemap-map" --data "$BUILD/seed-sim" --save-graph "$SEEDS/fuzz_scan_graph/sim.graph" \
    >/dev/null 2>&1
  for compression in none zstd lz4; do  # ROS 2 bags of the same scans, each chunk kind
    "$TOOLS/densemap-sim" --out "$BUILD/seed-sim" --scene indoor --sensor vlp16 --columns 40 \
      --scans 2 --gt-resolution 0 --mcap "$SEEDS/fuzz_mcap/sim_$compression.mcap" \
      --mcap-compression "$compression" >/dev/null 2>&1
  done
  "$TOOLS/densemap-sim" --out "$BUILD/seed-sim" --scene indoor --sensor vlp16 --columns 40 \
    --scans 2 --gt-resolution 0 --mcap "$SEEDS/fuzz_db3/sim.db3" >/dev/null 2>&1
else
  echo "fuzz.sh: no $TOOLS/densemap-sim: fuzz_scan_graph, fuzz_mcap and fuzz_db3 start without seeds"
fi
mkdir -p "$BUILD/artifacts"
total_runs=0
printf '%-22s %12s %10s %s\n' target executions exec/s result
for t in "${TARGETS[@]}"; do
  mkdir -p "$BUILD/corpus/$t"
  log="$BUILD/artifacts/$t.log"
  rc=0
  "$BUILD/bin/$t" -max_total_time="$SECONDS_PER" -timeout=10 -rss_limit_mb=2048 \
    -artifact_prefix="$BUILD/artifacts/$t-" "$BUILD/corpus/$t" "$SEEDS/$t" \
    >"$log" 2>&1 || rc=$?
  runs=$(grep -oE 'Done [0-9]+ runs' "$log" | grep -oE '[0-9]+' | tail -1 || true)
  runs=${runs:-0}
  total_runs=$((total_runs + runs))
  result=ok
  [ "$rc" -eq 0 ] || result="FAILED (exit $rc, see $log)"
  printf '%-22s %12s %10s %s\n' "$t" "$runs" "$((runs / (SECONDS_PER > 0 ? SECONDS_PER : 1)))" "$result"
  if [ "$rc" -ne 0 ]; then
    grep -E "ERROR|SUMMARY|Test unit written" "$log" | head -5 >&2
    exit 1
  fi
done
echo "fuzz.sh: ${#TARGETS[@]} targets, ${SECONDS_PER} s each, $total_runs executions, no crash"
