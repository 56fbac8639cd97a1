#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz) with clang and AddressSanitizer into build-fuzz/ and
# runs each for SECONDS on its committed seeds (tests/fuzz/corpus/<target>); new inputs go to
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
  fuzz_scan_validation fuzz_point_cloud2)
TARGETS=("$@")
[ ${#TARGETS[@]} -gt 0 ] || TARGETS=("${ALL[@]}")
# Debian 12's clang 16 with libstdc++ 12: <expected> wants __cpp_concepts >= 202002, which clang
# 16 implements (P0848) but does not announce.
CXXFLAGS_FUZZ="-U__cpp_concepts -D__cpp_concepts=202002L -fsanitize=fuzzer-no-link,address"
launcher=()
if command -v ccache >/dev/null 2>&1; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang-16 -DCMAKE_CXX_COMPILER=clang++-16 "${launcher[@]}" \
  -DDENSEMAP_FUZZ=ON -DDENSEMAP_BUILD_TESTS=OFF -DDENSEMAP_BUILD_TOOLS=OFF \
  "-DCMAKE_CXX_FLAGS=$CXXFLAGS_FUZZ" "-DCMAKE_C_FLAGS=-fsanitize=fuzzer-no-link,address" >/dev/null
build_args=()
for t in "${TARGETS[@]}"; do build_args+=(--target "$t"); done
cmake --build "$BUILD" --parallel "$(nproc)" "${build_args[@]}" >"$BUILD/fuzz-build.log" 2>&1 || {
  tail -30 "$BUILD/fuzz-build.log" >&2
  echo "fuzz.sh: build failed" >&2
  exit 1
}
mkdir -p "$BUILD/artifacts"
total_runs=0
printf '%-22s %12s %10s %s\n' target executions exec/s result
for t in "${TARGETS[@]}"; do
  mkdir -p "$BUILD/corpus/$t" "tests/fuzz/corpus/$t"
  log="$BUILD/artifacts/$t.log"
  rc=0
  "$BUILD/bin/$t" -max_total_time="$SECONDS_PER" -timeout=10 -rss_limit_mb=2048 \
    -artifact_prefix="$BUILD/artifacts/$t-" "$BUILD/corpus/$t" "tests/fuzz/corpus/$t" \
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
