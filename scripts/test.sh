#!/usr/bin/env bash
# The one command that installs what densemap needs, builds it and runs every test
# (unit, integration, and realdata where ../shared/data exists; realdata tests skip with a
# message where it does not). Usage: scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
./scripts/install-deps.sh
./scripts/build.sh -DDENSEMAP_BUILD_TESTS=ON
built=$(date +%s)
echo "test.sh: build took $((built - start)) s"
BUILD_DIR=${DENSEMAP_BUILD_DIR:-build}
run_tests=(ctest --test-dir "$BUILD_DIR" --output-on-failure --parallel "$(nproc)" --timeout 900)
# As root, run every test in a private network namespace with only `lo`: DDS traffic cannot
# leave the machine even by mistake. Elsewhere the tests bind loopback themselves.
if [ "$(id -u)" -eq 0 ] && unshare -n true 2>/dev/null; then
  echo "test.sh: running tests in a private network namespace (loopback only)"
  unshare -n sh -c 'ip link set lo up && exec "$@"' sh "${run_tests[@]}"
else
  "${run_tests[@]}"
fi
echo "test.sh: tests took $(( $(date +%s) - built )) s; total $(( $(date +%s) - start )) s"
