#!/usr/bin/python3
"""The server and densemap-bench with and without an environment setting (such as
DENSEMAP_MALLOC=default, which turns the heap's huge pages off), alternated, --runs runs each.
Prints two markdown tables for docs/benchmarks.md:

1. scripts/realtime-check.sh at --rate Hz (the server with the replay client on the same cores):
   scans integrated, server p50 / p99, CPU ms a received scan, minor page faults;
2. densemap-bench on the same scans: p50 / p99 ms a scan, CPU s for the run (loading
   included), minor page faults.

Usage: scripts/server-env-benchmark.py DATA --env NAME=VALUE [--kind akimap_rays]
           [--resolution 0.1] [--max-range 30] [--rate 10] [--runs 3] [--server-only]
Run as root it runs each server inside `unshare -n` (loopback only). Binaries from
<build>/bin (DENSEMAP_BUILD_DIR, default build).
"""

import argparse
import os
import resource
import subprocess

from bench_stats import bench_lane, cpu_model, realtime_check, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"), "bin")


def with_env(setting):
    """This process' environment, plus NAME=VALUE when given."""
    env = dict(os.environ)
    if setting is not None:
        name, value = setting.split("=", 1)
        env[name] = value
    return env


def server(args, setting):
    """One realtime-check run: (integrated, received, p50, p99, CPU s, minor faults)."""
    env = dict(with_env(setting), BENCH="0", KIND=args.kind, DENSEMAP_BIN=BIN)
    integrated, dropped, p50, p99, cpu, faults, _ = realtime_check(
        ROOT, args.data, args.resolution, args.max_range, args.rate, env)
    return (integrated, integrated + dropped, p50, p99, cpu, faults)


def bench(args, setting):
    """One densemap-bench run: (p50, p99, CPU s, minor faults) of the child."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(
        [os.path.join(BIN, "densemap-bench"), "--data", args.data, "--resolution",
         str(args.resolution), "--max-range", str(args.max_range), "--threads", "2",
         "--methods", args.kind], env=with_env(setting), capture_output=True, text=True,
        check=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    p50, p99 = bench_lane(out, args.kind)
    return (p50, p99, cpu, after.ru_minflt - before.ru_minflt)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("--env", required=True, help="NAME=VALUE, set in the compared runs")
    p.add_argument("--kind", default="akimap_rays")
    p.add_argument("--resolution", type=float, default=0.1)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--server-only", action="store_true", help="no densemap-bench table")
    args = p.parse_args()
    if "=" not in args.env:
        p.error("--env takes NAME=VALUE")
    settings = [None, args.env]
    name = {None: "as built", args.env: args.env}
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; "
          f"{os.path.basename(os.path.normpath(args.data))} at {args.resolution:g} m / "
          f"{args.max_range:g} m, {args.kind}, 2 threads; {args.runs} runs, alternated "
          "(median, min .. max)\n")
    servers = {s: [] for s in settings}
    benches = {s: [] for s in settings}
    for _ in range(args.runs):
        for s in settings:
            servers[s].append(server(args, s))
        for s in settings:
            if not args.server_only:
                benches[s].append(bench(args, s))
    print(f"The server at {args.rate:g} Hz (scripts/realtime-check.sh):\n")
    print("| environment | scans integrated (per run) | server p50 ms | server p99 ms | "
          "server CPU ms a received scan | minor page faults |")
    print("|---|---|---|---|---|---|")
    for s in settings:
        runs = servers[s]
        print(f"| {name[s]} | {', '.join(f'{r[0]}/{r[1]}' for r in runs)} | "
              f"{spread([r[2] for r in runs])} | {spread([r[3] for r in runs])} | "
              f"{spread([1000.0 * r[4] / r[1] for r in runs], '{:.0f}')} | "
              f"{spread([r[5] for r in runs], '{:.0f}')} |")
    if args.server_only:
        return
    print("\ndensemap-bench on the same scans:\n")
    print("| environment | bench p50 ms | bench p99 ms | CPU s (loading included) | "
          "minor page faults |")
    print("|---|---|---|---|---|")
    for s in settings:
        runs = benches[s]
        print(f"| {name[s]} | {spread([r[0] for r in runs])} | {spread([r[1] for r in runs])} | "
              f"{spread([r[2] for r in runs], '{:.2f}')} | {spread([r[3] for r in runs], '{:.0f}')} |")


if __name__ == "__main__":
    main()
