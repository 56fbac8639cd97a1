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
ctest --test-dir "$BUILD_DIR" --output-on-failure --parallel "$(nproc)" --timeout 900
echo "test.sh: tests took $(( $(date +%s) - built )) s; total $(( $(date +%s) - start )) s"
