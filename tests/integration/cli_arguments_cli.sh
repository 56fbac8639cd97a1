#!/usr/bin/env bash
# The CLI checks its arguments before it looks for a server: with no server on the domain and a
# long discovery timeout, each malformed request ends at once with its reason and exit 1.
# Usage: cli_arguments_cli.sh CLI_BIN DOMAIN
set -euo pipefail
cli=$1 domain=$2
check() {  # check EXPECTED_MESSAGE ARGS...: the CLI fails within 10 s and says EXPECTED_MESSAGE
  local expected=$1 start out rc
  shift
  start=$(date +%s)
  rc=0
  out=$(timeout 30 "$cli" --domain-id "$domain" --timeout-ms 60000 "$@" 2>&1) || rc=$?
  if [ "$rc" -ne 1 ]; then
    echo "cli_arguments: densemap $* exited $rc (expected 1): $out"; exit 1
  fi
  if ! grep -qF -- "$expected" <<<"$out"; then
    echo "cli_arguments: densemap $* said '$out', not '$expected'"; exit 1
  fi
  if [ $(( $(date +%s) - start )) -gt 10 ]; then
    echo "cli_arguments: densemap $* took over 10 s: it waited for a server first"; exit 1
  fi
}
check "point coordinates come in threes" query point 1 2
check "point coordinates come in threes" query point
check "give xyz or --random, not both" query point 1 2 3 --random 5
check "inverted box: min > max on some axis" query bbox --min 1 1 1 --max 0 2 2
check "inverted box: min > max on some axis" clear-bbox --min 1 1 1 --max 0 2 2
check "box corner is NaN or Inf" query bbox --min 0 0 nan --max 1 1 1
check "ray origin, direction or range is NaN or Inf" query ray --origin 0 0 0 --direction inf 0 0
check "ray direction has zero length" query ray --origin 0 0 0 --direction 0 0 0 --range 10
check "ray range must be in (0, 10 km]" query ray --origin 0 0 0 --direction 1 0 0 --range -1
echo "cli_arguments: every malformed request refused before discovery"
