#!/usr/bin/env bash
# A directory named where a file is expected is a clear error
# (exit 1 or 2 and the reason), never an abort (before: uncaught std::ios_failure, rc 134).
# Starts no DDS participant: every command fails while reading its input.
# Usage: directory_inputs_cli.sh SERVER_BIN CLI_BIN MAP_BIN SIM_BIN
set -euo pipefail
server=$1 cli=$2 map=$3 sim=$4
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
expect_clear_error() {  # NAME COMMAND...
  local name=$1 rc=0
  shift
  "$@" >"$dir/out.txt" 2>&1 || rc=$?
  if [ "$rc" -ne 1 ] && [ "$rc" -ne 2 ]; then
    echo "$name: exit $rc, expected 1 or 2"; cat "$dir/out.txt"; exit 1
  fi
  grep -q "directory" "$dir/out.txt" || { echo "$name: no reason in:"; cat "$dir/out.txt"; exit 1; }
}
mkdir -p "$dir/empty"
expect_clear_error "server --check-config DIR" "$server" --check-config "$dir/empty"
expect_clear_error "render --in DIR" "$cli" render --in "$dir/empty" --out "$dir/x.png"
expect_clear_error "load --scenario DIR" "$cli" load --scenario "$dir/empty" --out "$dir/load"
# A dataset whose poses.txt is a directory.
"$sim" --out "$dir/data" --scans 1 >/dev/null 2>&1
rm -f "$dir/data/poses.txt" "$dir/data/poses_kitti.txt"
mkdir "$dir/data/poses.txt"
expect_clear_error "densemap-map with poses.txt DIR" "$map" --data "$dir/data" --out "$dir/m.bt"
expect_clear_error "replay with poses.txt DIR" "$cli" --domain-id 170 --timeout-ms 200 replay --data "$dir/data"
echo "directory_inputs_cli: ok"
