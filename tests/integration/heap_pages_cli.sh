#!/usr/bin/env bash
# densemap-server puts its heap on transparent huge pages: it starts itself again with
# glibc.malloc.hugetlb=1 added to GLIBC_TUNABLES (tunables already there kept), unless
# DENSEMAP_MALLOC=default, the kernel's transparent huge pages are "never", or GLIBC_TUNABLES
# names the tunable already. The debug log says which, with the tunables it runs with.
# Usage: heap_pages_cli.sh SERVER_BIN SOURCE_DIR
set -euo pipefail
server=$1
src=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
config=$src/config/densemap.textproto
run() {  # NAME EXPECTED_TEXT [ENV...]: the server checks the config; its log holds the text
  local name=$1 expected=$2
  shift 2
  env -u GLIBC_TUNABLES -u DENSEMAP_MALLOC "$@" "$server" --log-level debug \
    --check-config "$config" >"$dir/out.txt" 2>&1
  grep -qF -- "$expected" "$dir/out.txt" || { echo "$name: no '$expected' in:"; cat "$dir/out.txt"; exit 1; }
}
mode=/sys/kernel/mm/transparent_hugepage/enabled
if [ -r "$mode" ] && ! grep -q '\[never\]' "$mode"; then
  run "default" "heap on transparent huge pages (glibc.malloc.hugetlb=1; DENSEMAP_MALLOC=default turns them off) (GLIBC_TUNABLES=glibc.malloc.hugetlb=1)"
  run "other tunables kept" "(GLIBC_TUNABLES=glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1)" \
    GLIBC_TUNABLES=glibc.malloc.arena_max=2
else
  run "kernel off" "the kernel's transparent huge pages are off"
fi
run "opted out" "heap on 4 KiB pages (DENSEMAP_MALLOC=default) (GLIBC_TUNABLES=)" DENSEMAP_MALLOC=default
run "tunable named" "heap as GLIBC_TUNABLES sets glibc.malloc.hugetlb (GLIBC_TUNABLES=glibc.malloc.hugetlb=0)" \
  GLIBC_TUNABLES=glibc.malloc.hugetlb=0
# The restart keeps the arguments: the config is still checked.
grep -q "is valid: grid backend" "$dir/out.txt"
echo "heap_pages_cli: ok"
