#!/usr/bin/env bash
# Configures and builds densemap into build/ (Release with debug info, Ninja).
# Usage: [DENSEMAP_BUILD_TARGETS="t1 t2"] scripts/build.sh [extra cmake args...]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${DENSEMAP_BUILD_DIR:-build}
launcher=()
if command -v ccache >/dev/null 2>&1; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  # One cache for every checkout of the project: paths inside it are hashed relative to it, so a
  # fresh clone (CI's) reuses what another checkout compiled.
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$PWD} CCACHE_NOHASHDIR=${CCACHE_NOHASHDIR:-true}
fi
cmake -S . -B "$BUILD_DIR" -G Ninja "${launcher[@]}" "$@"
targets=()
for t in ${DENSEMAP_BUILD_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build "$BUILD_DIR" --parallel "$(nproc)" "${targets[@]}"
