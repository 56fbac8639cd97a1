#!/usr/bin/env bash
# `densemap query distance` and `densemap query path` against a server with its distance field
# (esdf), after replaying a simulated drive: a point in a wall reads 0 m, a point far from
# everything the maximum; a path through a wall is occupied (exit 3), a short one in the
# scanned free space free (exit 0); bad requests fail with their reason; a server without the
# field says how to turn it on.
# Usage: planner_queries_cli.sh SERVER_BIN CLI_BIN SIM_BIN DOMAIN
set -euo pipefail
server=$1 cli=$2 sim=$3 domain=$4
dir=$(mktemp -d)
pid=
trap '[ -n "$pid" ] && kill $pid 2>/dev/null; rm -rf "$dir"' EXIT
"$sim" --out "$dir/drive" --scene indoor --sensor vlp16 --scans 3 --gt-resolution 0 >/dev/null 2>&1
start() {  # start EXTRA-CONFIG
  printf 'dds { domain_id: %s network_interface: "lo" }\nsnapshot { path: "" }\nmap { resolution_m: 0.2 max_range_m: 25 }\n%s\n' \
    "$domain" "$1" >"$dir/server.textproto"
  "$server" --config "$dir/server.textproto" 2>"$dir/server.log" &
  pid=$!
}
stop() { kill -TERM "$pid"; wait "$pid"; pid=; }
q() { "$cli" --domain-id "$domain" "$@"; }

start 'esdf { enabled: true max_distance_m: 1.0 }'
q replay --data "$dir/drive" >"$dir/replay.txt" 2>&1 || { cat "$dir/replay.txt"; exit 1; }
# An occupied cell of the map: the first of a ray's hits along +y from the sensor's height.
q query ray --origin 5 10 1.2 --direction 0 1 0 --range 20 >"$dir/ray.txt"
read -r hx hy hz < <(sed -n 's/^hit at \([^ ]*\) \([^ ]*\) \([^,]*\),.*/\1 \2 \3/p' "$dir/ray.txt")
[ -n "$hx" ] || { echo "no wall found: $(cat "$dir/ray.txt")"; exit 1; }
q query distance "$hx" "$hy" "$hz" 500 500 500 >"$dir/distance.txt"
grep -q "^$hx $hy $hz: 0.000 m" "$dir/distance.txt" || { cat "$dir/distance.txt"; exit 1; }
grep -q "^500 500 500: 1.000 m (nothing within 1 m)" "$dir/distance.txt" || { cat "$dir/distance.txt"; exit 1; }
rc=0
q query path 5 10 1.2 "$hx" "$(awk -v y="$hy" 'BEGIN { print y + 1 }')" "$hz" --radius 0.3 >"$dir/path.txt" || rc=$?
[ "$rc" = 3 ] && grep -q "^occupied" "$dir/path.txt" && grep -q "first occupied cell" "$dir/path.txt" ||
  { echo "path through the wall: rc $rc"; cat "$dir/path.txt"; exit 1; }
rc=0
q query path 5 10 1.2 5 10.2 1.2 --radius 0.05 >"$dir/free.txt" || rc=$?
[ "$rc" = 0 ] && grep -q "^free" "$dir/free.txt" || { echo "short path: rc $rc"; cat "$dir/free.txt"; exit 1; }
if q query path 5 10 1.2 6 10 1.2 --radius -1 >"$dir/bad.txt" 2>&1; then exit 1; fi
grep -qi "radius" "$dir/bad.txt" || { cat "$dir/bad.txt"; exit 1; }
if q query distance 1 2 >"$dir/bad.txt" 2>&1; then exit 1; fi
grep -q "multiple of 3" "$dir/bad.txt" || { cat "$dir/bad.txt"; exit 1; }
stop

start ''
if q query distance 1 2 3 >"$dir/none.txt" 2>&1; then exit 1; fi
grep -q "esdf" "$dir/none.txt" || { cat "$dir/none.txt"; exit 1; }
stop
echo "planner_queries_cli: ok"
