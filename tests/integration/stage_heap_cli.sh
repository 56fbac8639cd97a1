#!/usr/bin/env bash
# A dense map's stage buffers stay in densemap-server's heap between scans: with
# pipeline.heap_keep_mb at its default (read from idl/densemap.proto), five scans at 0.1 m
# fault at most a third as many pages as with 0, where a heap gives its free top back to the
# system and the next stage faults it in again (stage_heap_probe).
# Usage: stage_heap_cli.sh STAGE_HEAP_PROBE SOURCE_DIR
set -euo pipefail
probe=$1
src=$2
keep=$(grep -oP 'heap_keep_mb = \d+ \[default = \K\d+' "$src/idl/densemap.proto")
faults() { "$probe" "$1" | sed -nE 's/^faults ([0-9]+) .*/\1/p'; }
kept=$(faults "$keep")
given=$(faults 0)
echo "stage_heap_cli: minor page faults of five scans: $kept keeping $keep MiB, $given keeping none"
if [ -z "$kept" ] || [ -z "$given" ] || [ $((3 * kept)) -ge "$given" ]; then
  echo "stage_heap_cli: keeping the stages' memory should fault at most a third as often"
  exit 1
fi
