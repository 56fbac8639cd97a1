#!/usr/bin/python3
"""Python against C++ on the same scans: densemap.Mapper (one insert_point_cloud per scan from
NumPy float32 arrays) against densemap-bench's lane of the same method and threads, and the
Python map's .bt against densemap-map's, run after run (alternated, so both see the machine in
the same state). Prints a markdown table for docs/benchmarks.md.

Usage: scripts/python-benchmark.py [--data DIR] [--first 20] [--limit 80] [--resolution 0.2]
                                   [--max-range 30] [--threads 2] [--runs 3]
The module is taken from <build>/python (DENSEMAP_BUILD_DIR, default build); the data from
$DENSEMAP_DATA_DIR/balm-realworld (DENSEMAP_DATA_DIR defaults to ../shared/data).
"""

import argparse
import filecmp
import json
import os
import platform
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
from bench_stats import percentile  # noqa: E402


def python_run(scans, args, bt, versioned_reads=False):
    mapper = densemap.Mapper(resolution=args.resolution, max_range=args.max_range,
                             threads=args.threads, versioned_reads=versioned_reads)
    times = []
    for points, origin in scans:
        start = time.perf_counter()
        mapper.insert_point_cloud(points, origin)
        times.append((time.perf_counter() - start) * 1000.0)
    mapper.save(bt)
    return times, mapper.known_cells


def bench_run(args, out):
    subprocess.run([os.path.join(BUILD, "bin", "densemap-bench"), "--data", args.data,
                    "--first", str(args.first), "--limit", str(args.limit),
                    "--resolution", str(args.resolution), "--max-range", str(args.max_range),
                    "--methods", "raycast", "--backend", "grid", "--threads", str(args.threads),
                    "--cache-probe-mib", "0", "--json", out],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run = json.load(open(out))["runs"][0]
    return run["ms_per_scan_p50"], run["ms_per_scan_p99"]


def main():
    data_dir = os.environ.get("DENSEMAP_DATA_DIR", os.path.join(ROOT, "..", "shared", "data"))
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default=os.path.join(data_dir, "balm-realworld"))
    p.add_argument("--first", type=int, default=0)
    p.add_argument("--limit", type=int, default=0)
    p.add_argument("--resolution", type=float, default=0.2)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runs", type=int, default=5)
    args = p.parse_args()
    if not os.path.isdir(args.data):
        sys.exit(f"python-benchmark: no dataset at {args.data} (give --data or DENSEMAP_DATA_DIR)")
    reader = densemap.read_scans(args.data, first=args.first, limit=args.limit)
    scans = [(np.ascontiguousarray(s.points_world, dtype=np.float32), s.origin) for s in reader]
    work = tempfile.mkdtemp(prefix="densemap-python-bench.")
    reference = os.path.join(work, "densemap-map.bt")
    subprocess.run([os.path.join(BUILD, "bin", "densemap-map"), "--data", args.data,
                    "--first", str(args.first), "--limit", str(args.limit),
                    "--resolution", str(args.resolution), "--max-range", str(args.max_range),
                    "--threads", str(args.threads), "--out", reference],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), platform.processor())
    print(f"Machine: {cpu}, {os.cpu_count()} vCPUs; {time.strftime('%Y-%m-%d', time.gmtime())}")
    print(f"Data: {os.path.basename(os.path.normpath(args.data))}, {len(scans)} scans from "
          f"position {args.first}, {args.resolution} m, max range {args.max_range} m, "
          f"{args.threads} threads, grid backend, raycast")
    print()
    print("| run | densemap-bench p50 / p99 ms | Python Mapper p50 / p99 ms | Python / bench p50 "
          "| Python, versioned_reads=True p50 / p99 ms | .bt equals densemap-map's |")
    print("|---|---|---|---|---|---|")
    ratios, versioned_ratios = [], []
    for run in range(1, args.runs + 1):
        bench_p50, bench_p99 = bench_run(args, os.path.join(work, f"bench-{run}.json"))
        bt = os.path.join(work, f"python-{run}.bt")
        times, _ = python_run(scans, args, bt)
        versioned, _ = python_run(scans, args, bt + ".versioned.bt", versioned_reads=True)
        py_p50, py_p99 = percentile(times, 50), percentile(times, 99)
        v_p50, v_p99 = percentile(versioned, 50), percentile(versioned, 99)
        same = (filecmp.cmp(bt, reference, shallow=False)
                and filecmp.cmp(bt + ".versioned.bt", reference, shallow=False))
        ratios.append(py_p50 / bench_p50)
        versioned_ratios.append(v_p50 / bench_p50)
        print(f"| {run} | {bench_p50:.2f} / {bench_p99:.2f} | {py_p50:.2f} / {py_p99:.2f} "
              f"| {py_p50 / bench_p50:.3f} | {v_p50:.2f} / {v_p99:.2f} "
              f"| {'yes (byte for byte)' if same else 'NO'} |")
    print()
    print(f"Python / bench p50: median {statistics.median(ratios):.3f}, {min(ratios):.3f} .. "
          f"{max(ratios):.3f} over {len(ratios)} runs; with versioned_reads=True: median "
          f"{statistics.median(versioned_ratios):.3f}, {min(versioned_ratios):.3f} .. "
          f"{max(versioned_ratios):.3f}.")


if __name__ == "__main__":
    main()
