#!/usr/bin/python3
"""Spatial shards on one dataset: a log-odds densemap.Mapper over all of space against two whose
boxes (map.bounds) split it at a plane x = X, each fed every scan as a shard server is. Checks
that the two shards' cells together are the whole map's, cell for cell (keys and log-odds), and
prints a markdown table for docs/benchmarks.md: each lane's CPU a scan and insert p50 / p99,
with its known cells. Each lane runs in a process of its own; lanes alternate over the runs.

Usage: scripts/shard-benchmark.py DATA [--first 20 --limit 80] [--resolution 0.2]
                                  [--max-range 30] [--split-x X] [--threads 2] [--runs 3]
--split-x defaults to the median of the scans' origins along x (about half the path each).
The module is taken from <build>/python (DENSEMAP_BUILD_DIR, default build).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

from bench_stats import cpu_model, percentile, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))
FAR = 1.0e4  # the boxes' open sides, m

# One lane, in a process of its own: inserts every scan, saves its known cells.
CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import densemap
(data, first, limit, resolution, max_range, threads, bounds, out) = (
    sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]),
    int(sys.argv[7]), json.loads(sys.argv[8]), sys.argv[9])
reader = densemap.read_scans(data)
end = len(reader) if limit == 0 else min(len(reader), first + limit)
scans = [(np.ascontiguousarray(reader[i].points_world, dtype=np.float32), reader[i].origin)
         for i in range(first, end)]
mapper = densemap.Mapper(resolution=resolution, max_range=max_range, threads=threads,
                         bounds=None if bounds is None else (tuple(bounds[0]), tuple(bounds[1])))
times = []
before = resource.getrusage(resource.RUSAGE_SELF)
for points, origin in scans:
    start = time.perf_counter()
    mapper.insert_point_cloud(points, origin)
    times.append((time.perf_counter() - start) * 1e3)
after = resource.getrusage(resource.RUSAGE_SELF)
centres, log_odds = mapper.cells()
np.savez(out, centres=centres, log_odds=log_odds)
print(json.dumps({"times": times, "scans": len(scans),
                  "cpu_s": after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime}))
"""

ORIGINS = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
import densemap
reader = densemap.read_scans(sys.argv[2])
first, limit = int(sys.argv[3]), int(sys.argv[4])
end = len(reader) if limit == 0 else min(len(reader), first + limit)
print(json.dumps([float(reader[i].origin[0]) for i in range(first, end)]))
"""


def lane(args, bounds, out):
    result = subprocess.run(
        [sys.executable, "-c", CHILD, os.path.join(BUILD, "python"), args.data, str(args.first),
         str(args.limit), str(args.resolution), str(args.max_range), str(args.threads),
         json.dumps(bounds), out],
        capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit("shard-benchmark: a lane failed:\n" + result.stderr[-2000:])
    return json.loads(result.stdout.strip().splitlines()[-1])


def cells(path):
    import numpy as np
    data = np.load(path)
    keys = np.round(data["centres"].astype(np.float64) / ARGS.resolution - 0.5).astype(np.int64)
    return {tuple(k): v for k, v in zip(keys.tolist(), data["log_odds"].tolist())}


def main():
    global ARGS
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--limit", type=int, default=0, help="0: all scans")
    p.add_argument("--resolution", type=float, default=0.2)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--split-x", type=float, default=None)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runs", type=int, default=3)
    args = ARGS = p.parse_args()
    if args.runs < 1 or args.resolution <= 0:
        sys.exit("shard-benchmark: --runs >= 1 and --resolution > 0")
    if args.split_x is None:
        origins = json.loads(subprocess.run(
            [sys.executable, "-c", ORIGINS, os.path.join(BUILD, "python"), args.data,
             str(args.first), str(args.limit)], capture_output=True, text=True,
            check=True).stdout)
        if not origins:
            sys.exit("shard-benchmark: no scans in " + args.data)
        args.split_x = percentile(origins, 50)
    x = args.split_x
    lanes = {
        "whole (no box)": None,
        "west shard (x <= %.2f m)" % x: [[-FAR, -FAR, -FAR], [x, FAR, FAR]],
        "east shard (x > %.2f m)" % x: [[x, -FAR, -FAR], [FAR, FAR, FAR]],
    }
    results = {name: [] for name in lanes}
    differing = None
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(args.runs):
            names = list(lanes) if run % 2 == 0 else list(reversed(lanes))
            for name in names:
                out = os.path.join(tmp, "%d_%d.npz" % (run, list(lanes).index(name)))
                r = lane(args, lanes[name], out)
                r["out"] = out
                results[name].append(r)
                print("shard-benchmark: run %d, %s: %.1f CPU-s" % (run + 1, name, r["cpu_s"]),
                      file=sys.stderr)
            whole, west, east = (cells(results[n][run]["out"]) for n in lanes)
            both = set(west) & set(east)
            union = dict(west)
            union.update(east)
            bad = len(both) + sum(1 for k in set(whole) | set(union)
                                  if whole.get(k) != union.get(k))
            differing = bad if differing is None else max(differing, bad)
            known = {n: c for n, c in zip(lanes, (len(whole), len(west), len(east)))}
            for name in lanes:
                results[name][run]["known"] = known[name]
    print("%s, %s, %d threads; %d scans of %s from %d, %.2f m / %.0f m; split at x = %.2f m; "
          "%d runs, median (min .. max)\n" % (
              cpu_model(), "CPU: user + system time of each lane's process over its inserts",
              args.threads,
              results[list(lanes)[0]][0]["scans"], os.path.basename(os.path.normpath(args.data)),
              args.first, args.resolution, args.max_range, x, args.runs))
    print("| lane | CPU ms a scan | insert p50 ms | insert p99 ms | known cells | CPU / whole |")
    print("|---|---|---|---|---|---|")
    whole_cpu = [r["cpu_s"] * 1e3 / r["scans"] for r in results[list(lanes)[0]]]
    for name in lanes:
        rs = results[name]
        cpu = [r["cpu_s"] * 1e3 / r["scans"] for r in rs]
        p50 = [percentile(r["times"], 50) for r in rs]
        p99 = [percentile(r["times"], 99) for r in rs]
        ratio = [c / w for c, w in zip(cpu, whole_cpu)]
        print("| %s | %s | %s | %s | %d | %s |" % (name, spread(cpu), spread(p50), spread(p99),
                                                  rs[0]["known"], spread(ratio, "{:.2f}")))
    print("\nCells where the two shards together differ from the whole map (keys or log-odds, "
          "or held by both), worst run: %d" % differing)
    return 0 if differing == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
