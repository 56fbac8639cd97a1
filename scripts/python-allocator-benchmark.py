#!/usr/bin/python3
"""What the Python module's allocator setting saves: densemap.Mapper inserting the same scans in
a fresh process with the module's setting (scan-sized buffers kept in the heap) and with glibc's
defaults (DENSEMAP_MALLOC=default), runs alternated. Prints a markdown table for
docs/benchmarks.md: insert p50 / p99, the process's CPU seconds and minor page faults over the
inserts.

Usage: scripts/python-allocator-benchmark.py DATA [--kind akimap_rays] [--resolution 0.2]
                                             [--max-range 80] [--threads 2] [--runs 3]
The module is taken from <build>/python (DENSEMAP_BUILD_DIR, default build).
"""

import argparse
import json
import os
import subprocess
import sys

from bench_stats import cpu_model, percentile, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))

# One run, in a process of its own (the allocator's setting is the process's).
CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import densemap
data, kind, resolution, max_range, threads = sys.argv[2], sys.argv[3], float(sys.argv[4]), float(sys.argv[5]), int(sys.argv[6])
scans = [(np.ascontiguousarray(s.points_world, dtype=np.float32), s.origin)
         for s in densemap.read_scans(data)]
mapper = densemap.Mapper(resolution=resolution, max_range=max_range, kind=kind, threads=threads)
times = []
before = resource.getrusage(resource.RUSAGE_SELF)
for points, origin in scans:
    start = time.perf_counter()
    mapper.insert_point_cloud(points, origin)
    times.append((time.perf_counter() - start) * 1e3)
after = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"times": times,
                  "cpu_s": after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime,
                  "faults": after.ru_minflt - before.ru_minflt}))
"""


def run(args, default_malloc):
    env = dict(os.environ)
    env.pop("DENSEMAP_MALLOC", None)
    if default_malloc:
        env["DENSEMAP_MALLOC"] = "default"
    out = subprocess.run([sys.executable, "-c", CHILD, os.path.join(BUILD, "python"), args.data,
                          args.kind, str(args.resolution), str(args.max_range), str(args.threads)],
                         env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("--kind", default="akimap_rays")
    p.add_argument("--resolution", type=float, default=0.2)
    p.add_argument("--max-range", type=float, default=80.0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--runs", type=int, default=3)
    args = p.parse_args()
    results = {False: [], True: []}
    for _ in range(args.runs):
        for default_malloc in (False, True):
            results[default_malloc].append(run(args, default_malloc))
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; "
          f"{os.path.basename(os.path.normpath(args.data))}, Mapper(kind={args.kind!r}, "
          f"resolution={args.resolution:g}, max_range={args.max_range:g}, threads={args.threads}); "
          f"{args.runs} runs alternated (median, min .. max)\n")
    print("| process's malloc | insert p50 ms | insert p99 ms | CPU s | minor page faults |")
    print("|---|---|---|---|---|")
    for default_malloc, name in ((False, "the module's setting"),
                                 (True, "glibc's defaults (DENSEMAP_MALLOC=default)")):
        rs = results[default_malloc]
        print(f"| {name} | {spread([percentile(r['times'], 50) for r in rs])} | "
              f"{spread([percentile(r['times'], 99) for r in rs])} | "
              f"{spread([r['cpu_s'] for r in rs])} | "
              f"{spread([float(r['faults']) for r in rs], '{:.0f}')} |")


if __name__ == "__main__":
    main()
