#!/usr/bin/env bash
# The one command that installs what densemap needs, builds it and runs every test
# (unit, integration, and realdata where ../shared/data exists; realdata tests skip with a
# message where it does not). Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
./scripts/install-deps.sh
# The Foxglove test's client packages (@foxglove/ws-protocol and Foxglove's decoders), pinned by
# tests/foxglove/package-lock.json; the one step that needs the npm registry.
(cd tests/foxglove && npm ci --no-audit --no-fund --loglevel=error)
./scripts/build.sh -DDENSEMAP_BUILD_TESTS=ON
built=$(date +%s)
echo "test.sh: build took $((built - start)) s"
BUILD_DIR=${DENSEMAP_BUILD_DIR:-build}
# As root, run every test in a private network namespace with only `lo`: DDS traffic cannot
# leave the machine even by mistake. Elsewhere the tests bind loopback themselves.
isolated() {
  if [ "$(id -u)" -eq 0 ] && unshare -n true 2>/dev/null; then
    unshare -n sh -c 'ip link set lo up && exec "$@"' sh "$@"
  else
    "$@"
  fi
}
echo "test.sh: tests run in a private network namespace (loopback only) when root"
isolated ctest --test-dir "$BUILD_DIR" --output-on-failure --parallel "$(nproc)" --timeout 900
tested=$(date +%s)
echo "test.sh: tests took $((tested - built)) s"
# A 2-minute soak (scripts/soak.sh MINUTES for longer ones): fails on RSS growth or p99 drift.
DENSEMAP_BIN="$BUILD_DIR/bin" SOAK_OUT=/tmp/densemap-soak-ci isolated ./scripts/soak.sh 2
soaked=$(date +%s)
echo "test.sh: soak took $((soaked - tested)) s"
# libFuzzer, CI-sized: every parser of outside bytes for 10 s on its committed seeds.
./scripts/fuzz.sh 10
fuzzed=$(date +%s)
echo "test.sh: fuzzing took $((fuzzed - soaked)) s"
# The .debs (contents, lintian, dpkg -i as root), the SDK in a temporary prefix and the example
# client built against it.
isolated ./scripts/check-packages.sh
echo "test.sh: packages took $(( $(date +%s) - fuzzed )) s; total $(( $(date +%s) - start )) s"
