#!/usr/bin/env bash
# densemap-bench's per-lane kernel settings (KIND@set=NAME=VALUE[:NAME=VALUE]), as a user runs
# them: a lane with the default's own value gives the default's map bit for bit (evidence
# digest), another value another map, in the same run; a bad setting is a clear error, exit 2.
# Usage: bench_kernel_variants_cli.sh SIM_BIN BENCH_BIN
set -euo pipefail
sim=$1
bench=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT

"$sim" --out "$dir/scene" --scene structured --sensor os0-64 --columns 256 --scans 3 \
  --points-per-scan 1500 --max-range 8 --gt-resolution 0 --threads 2 >/dev/null 2>&1
"$bench" --data "$dir/scene" --resolution 0.1 --max-range 8 --threads 2 \
  --methods akimap_rays,akimap_rays@set=hit_stencil_steps=4,akimap_rays@set=hit_stencil_steps=0:shared_fit_min_hits=0 \
  >"$dir/out.txt" 2>&1
digest() { grep -F "$1/kernel:" "$dir/out.txt" | grep -o 'evidence digest [0-9a-f]*' | cut -d' ' -f3; }
default=$(digest "akimap_rays")
same=$(digest "akimap_rays@set=hit_stencil_steps=4")
other=$(digest "akimap_rays@set=hit_stencil_steps=0:shared_fit_min_hits=0")
[ -n "$default" ] && [ -n "$same" ] && [ -n "$other" ]
[ "$default" = "$same" ] || { echo "the default's value gave another map: $default $same"; exit 1; }
[ "$default" != "$other" ] || { echo "other settings gave the same map"; exit 1; }
# Bad settings: named in the error, exit 2, nothing run.
for bad in "akimap_rays@set=widht=3" "akimap_rays@set=hit_stencil_steps=7" "akimap_rays@sett"; do
  code=0
  "$bench" --data "$dir/scene" --resolution 0.1 --methods "$bad" >/dev/null 2>"$dir/err.txt" ||
    code=$?
  [ "$code" -eq 2 ] || { echo "$bad: exit $code, expected 2"; exit 1; }
  grep -qF "${bad#*@}" "$dir/err.txt" || grep -qF "$bad" "$dir/err.txt" ||
    { echo "$bad: the error does not name it:"; cat "$dir/err.txt"; exit 1; }
done
# METHOD@tN: the lane runs on N threads (the table's thr column), the same map as OctoMap's;
# OctoMap on more than one thread is refused, exit 2.
"$bench" --data "$dir/scene" --resolution 0.1 --max-range 8 --backend grid \
  --methods octomap,raycast@t1,raycast@t2 >"$dir/threads.txt" 2>&1
for lane in "raycast@t1 1" "raycast@t2 2"; do
  set -- $lane
  awk -v m="$1" -v t="$2" '$1 == m && $2 == "grid" && $4 == t && $12 == "0" {found = 1}
    END {exit !found}' "$dir/threads.txt" ||
    { echo "$1: not on $2 threads with 0 cells differing:"; cat "$dir/threads.txt"; exit 1; }
done
# The cache probes before and after the lanes: a time for each vCPU.
for when in before after; do
  grep -qE "^cache probe $when the lanes \(4 MiB pointer chase, ns a step\): vCPU 0 [0-9.]+" \
    "$dir/threads.txt" || { echo "no cache probe $when the lanes:"; cat "$dir/threads.txt"; exit 1; }
done
code=0
"$bench" --data "$dir/scene" --resolution 0.1 --methods octomap@t2 >/dev/null 2>"$dir/err.txt" ||
  code=$?
[ "$code" -eq 2 ] && grep -qF "octomap@t2" "$dir/err.txt" ||
  { echo "octomap@t2: exit $code, expected 2 naming it"; exit 1; }
