#!/usr/bin/env bash
# densemap-server --check-config: 0 and a summary for a good config; 2 and the reason for a bad
# one, a broken snapshot or a snapshot directory that does not exist. Starts no DDS participant.
# Usage: check_config_cli.sh SERVER_BIN SOURCE_DIR
set -euo pipefail
server=$1
src=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
expect_fail() {  # NAME EXPECTED_TEXT CONFIG
  local rc=0
  "$server" --check-config "$3" >"$dir/out.txt" 2>&1 || rc=$?
  [ "$rc" -eq 2 ] || { echo "$1: exit $rc, expected 2"; cat "$dir/out.txt"; exit 1; }
  grep -q "$2" "$dir/out.txt" || { echo "$1: no '$2' in:"; cat "$dir/out.txt"; exit 1; }
}

"$server" --check-config "$src/config/densemap.textproto" >"$dir/out.txt"
grep -q "is valid: grid backend, log_odds map at 0.2 m" "$dir/out.txt"

printf 'map { resolution_m: -1 }\n' >"$dir/neg.textproto"
expect_fail "negative resolution" "resolution" "$dir/neg.textproto"
printf 'map { resolutoin_m: 0.1 }\n' >"$dir/typo.textproto"
expect_fail "unknown field" "resolutoin_m" "$dir/typo.textproto"
printf 'snapshot { path: "%s/no/such/dir/map.dmap" }\n' "$dir" >"$dir/nodir.textproto"
expect_fail "missing snapshot directory" "does not exist" "$dir/nodir.textproto"
printf 'not a dmap' >"$dir/bad.dmap"
printf 'snapshot { path: "%s/bad.dmap" }\n' "$dir" >"$dir/badsnap.textproto"
expect_fail "corrupt snapshot" "snapshot" "$dir/badsnap.textproto"
printf 'upsample { enabled: true method: "iln" model: "%s/none.pb" }\n' "$dir" >"$dir/model.textproto"
expect_fail "missing ILN model" "none.pb" "$dir/model.textproto"
# A non-loopback interface without security: refused unless explicitly allowed (then valid).
printf 'dds { network_interface: "eth0" }\n' >"$dir/remote.textproto"
expect_fail "insecure remote" "allow_insecure_remote" "$dir/remote.textproto"
printf 'dds { network_interface: "eth0" allow_insecure_remote: true }\nsnapshot { path: "" }\n' \
  >"$dir/remote-ok.textproto"
"$server" --check-config "$dir/remote-ok.textproto" >/dev/null
# The Foxglove endpoint: loopback by default; another address needs TLS or an explicit opt-out.
printf 'foxglove { enabled: true address: "10.1.2.3" }\n' >"$dir/fox.textproto"
expect_fail "foxglove remote" "allow_insecure_remote" "$dir/fox.textproto"
printf 'foxglove { enabled: true address: "10.1.2.3" allow_insecure_remote: true }\nsnapshot { path: "" }\n' \
  >"$dir/fox-ok.textproto"
"$server" --check-config "$dir/fox-ok.textproto" >/dev/null
printf 'foxglove { enabled: true address: "robot.local" }\n' >"$dir/fox-name.textproto"
expect_fail "foxglove address" "not an IPv4 or IPv6 address" "$dir/fox-name.textproto"
printf 'foxglove { enabled: true address: "::1" port: 0 }\n' >"$dir/fox-port.textproto"
expect_fail "foxglove port" "foxglove.port" "$dir/fox-port.textproto"
printf 'foxglove { enabled: true certificate_chain: "%s/none.pem" }\n' "$dir" >"$dir/fox-tls.textproto"
expect_fail "foxglove half TLS" "both certificate_chain and private_key" "$dir/fox-tls.textproto"
printf 'foxglove { enabled: true certificate_chain: "%s/none.pem" private_key: "%s/none.key" }\n' \
  "$dir" "$dir" >"$dir/fox-tls2.textproto"
expect_fail "foxglove TLS files" "cannot read" "$dir/fox-tls2.textproto"
# A remote interface with a security block (make-pki.sh's server files): valid.
if command -v openssl >/dev/null; then
  "$src/scripts/make-pki.sh" --days 1 "$dir/pki" >/dev/null
  p="$dir/pki"
  printf 'dds { network_interface: "eth0" }\nsnapshot { path: "" }\nsecurity { identity_ca: "%s" identity_certificate: "%s" private_key: "%s" permissions_ca: "%s" governance: "%s" permissions: "%s" }\n' \
    "$p/ca.pem" "$p/server.pem" "$p/server.key" "$p/ca.pem" "$p/governance.p7s" "$p/permissions.p7s" \
    >"$dir/secure.textproto"
  "$server" --check-config "$dir/secure.textproto" | grep -q "on eth0 with DDS Security"
  sed 's#/server.key#/none.key#' "$dir/secure.textproto" >"$dir/nokey.textproto"
  expect_fail "missing private key" "security.private_key" "$dir/nokey.textproto"
fi
# A directory where a file is expected, values that
# cannot work, and a snapshot directory the server could not write are refused with the reason.
expect_fail "directory as config" "is a directory" "$dir"
printf 'snapshot { path: "%s" }\n' "$dir" >"$dir/snapdir.textproto"
expect_fail "directory as snapshot" "is a directory" "$dir/snapdir.textproto"
printf 'pipeline { reserve_blocks: 10000000 }\n' >"$dir/reserve.textproto"
expect_fail "huge reserve_blocks" "reserve_blocks must be at most" "$dir/reserve.textproto"
printf 'pipeline { max_query_cells: 18446744073709551615 }\n' >"$dir/cells.textproto"
expect_fail "unbounded max_query_cells" "max_query_cells must be in" "$dir/cells.textproto"
printf 'pipeline { queue_budget_mb: 100000 }\n' >"$dir/queue.textproto"
expect_fail "huge queue_budget_mb" "queue_budget_mb must be in 16..65536" "$dir/queue.textproto"
printf 'pipeline { heap_keep_mb: 4096 }\n' >"$dir/keep.textproto"
expect_fail "huge heap_keep_mb" "heap_keep_mb must be in 0..1024" "$dir/keep.textproto"
printf 'snapshot { autosave_period_s: 1e-9 }\n' >"$dir/autosave.textproto"
expect_fail "continuous autosave" "autosave_period_s must be 0" "$dir/autosave.textproto"
printf 'map { max_range_m: -1 }\n' >"$dir/range.textproto"
expect_fail "unlimited range" "no unlimited range" "$dir/range.textproto"
printf 'map { resolution_m: 1e-9 }\n' >"$dir/tiny.textproto"
expect_fail "tiny resolution" "got 1e-09" "$dir/tiny.textproto"
printf 'map { decay { enabled: true clock: "wall" } }\n' >"$dir/clock.textproto"
expect_fail "unknown decay clock" "map.decay.clock must be" "$dir/clock.textproto"
printf 'map { decay { enabled: true period_s: 0 } }\n' >"$dir/period.textproto"
expect_fail "decay period 0" "map.decay: period_s must be in" "$dir/period.textproto"
printf 'map { kind: "akimap" decay { enabled: true } }\n' >"$dir/kdecay.textproto"
expect_fail "decay on a kernel map" "decay needs the log_odds map kind" "$dir/kdecay.textproto"
printf 'map { decay { enabled: true after_s: 30 } }\n' >"$dir/decay.textproto"
"$server" --check-config "$dir/decay.textproto" >/dev/null
if [ "$(id -u)" -ne 0 ]; then  # root may write anywhere: the check is for other users
  mkdir -p "$dir/ro" && chmod 0555 "$dir/ro"
  printf 'snapshot { path: "%s/ro/map.dmap" }\n' "$dir" >"$dir/ro.textproto"
  expect_fail "unwritable snapshot directory" "not writable" "$dir/ro.textproto"
fi
# --config and --check-config together: a usage error.
if "$server" --config "$src/config/densemap.textproto" --check-config "$src/config/densemap.textproto" \
  >/dev/null 2>&1; then
  echo "--config with --check-config should be refused"
  exit 1
fi
echo "check_config_cli: ok"
