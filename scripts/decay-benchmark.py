#!/usr/bin/python3
"""What a map that forgets (decay_after / map.decay) keeps and drops, and what it costs: a
simulated drive past people walking (densemap-sim --walkers), mapped with densemap.Mapper
without decay and with each decay setting, scans 0.1 s apart by their stamps. At the end it
counts the occupied cells that the map of the same drive without walkers (no decay) does not
have ("trail cells": where walkers were) and those it has (the static world still held), and
the insert time per scan. Prints a markdown table for docs/benchmarks.md.

Usage: scripts/decay-benchmark.py [--scans 150] [--walkers 4] [--resolution 0.1]
                                  [--max-range 30] [--threads 2] [--runs 3]
The module is taken from <build>/python (DENSEMAP_BUILD_DIR, default build), densemap-sim from
<build>/bin.
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))
sys.path.insert(0, os.path.join(BUILD, "python"))
import numpy as np  # noqa: E402

import densemap  # noqa: E402
from bench_stats import cpu_model, percentile  # noqa: E402

# (label, decay_after s, decay_period s); None: no decay.
SETTINGS = [("off (OctoMap's map)", None, 1.0), ("after 2 s, a miss every 0.5 s", 2.0, 0.5),
            ("after 5 s, a miss every 1 s", 5.0, 1.0)]


def run(scans, static, args, decay_after, decay_period):
    mapper = densemap.Mapper(resolution=args.resolution, max_range=args.max_range,
                             threads=args.threads, decay_after=decay_after,
                             decay_period=decay_period)
    times = []
    for i, scan in enumerate(scans):
        t0 = time.perf_counter()
        mapper.insert_point_cloud(scan.points_world, scan.origin, stamp=0.1 * i)
        times.append((time.perf_counter() - t0) * 1e3)
    centres = mapper.occupied_cells()
    in_static = static.occupancy(centres) > 0.5
    return int((~in_static).sum()), int(in_static.sum()), times


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scans", type=int, default=150)
    parser.add_argument("--walkers", type=int, default=4)
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--max-range", type=float, default=30.0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    sim = os.path.join(BUILD, "bin", "densemap-sim")
    with tempfile.TemporaryDirectory(prefix="densemap-decay.") as out:
        print(f"decay-benchmark: simulating {args.scans} scans with {args.walkers} walkers ...",
              file=sys.stderr)
        for walkers in (args.walkers, 0):
            subprocess.run([sim, "--out", os.path.join(out, str(walkers)), "--scene", "indoor",
                            "--sensor", "os128", "--columns", "1024", "--scans", str(args.scans),
                            "--walkers", str(walkers), "--gt-resolution", "0"],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        scans = list(densemap.read_scans(os.path.join(out, str(args.walkers))))
        static = densemap.Mapper(resolution=args.resolution, max_range=args.max_range,
                                 threads=args.threads)
        for scan in densemap.read_scans(os.path.join(out, "0")):
            static.insert(scan)
        results = {label: [] for label, _, _ in SETTINGS}
        for r in range(args.runs):  # settings alternated within each run
            for label, after, period in SETTINGS:
                print(f"decay-benchmark: run {r + 1}/{args.runs}: {label}", file=sys.stderr)
                results[label].append(run(scans, static, args, after, period))
    commit = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; "
          f"commit {commit}; simulated indoor drive (os128, 1024 columns), {args.scans} scans "
          f"0.1 s apart, {args.walkers} walkers; {args.resolution} m / {args.max_range} m, "
          f"{args.threads} threads, {args.runs} runs (median, min .. max of the runs' p50)")
    print()
    print("| decay | trail cells at the end | static occupied cells kept | insert p50 ms "
          "(min .. max) | insert p99 ms |")
    print("|---|---|---|---|---|")
    for label, _, _ in SETTINGS:
        rows = results[label]
        p50s = [percentile(t, 50) for _, _, t in rows]
        p99s = [percentile(t, 99) for _, _, t in rows]
        trail, kept = rows[0][0], rows[0][1]
        assert all(row[0] == trail and row[1] == kept for row in rows), "maps differ run to run"
        print(f"| {label} | {trail} | {kept} | {statistics.median(p50s):.1f} "
              f"({min(p50s):.1f} .. {max(p50s):.1f}) | {statistics.median(p99s):.1f} |")


if __name__ == "__main__":
    np.seterr(invalid="ignore")
    main()
