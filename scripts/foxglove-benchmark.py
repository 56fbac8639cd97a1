#!/usr/bin/python3
"""What Foxglove viewers cost the server: scripts/realtime-check.sh on the same scans, without
the Foxglove endpoint and with it on and N clients subscribed to every channel from before the
first scan (one of them never reads), runs alternated. Prints a markdown table for
docs/benchmarks.md: scans integrated and dropped, the server's latency (receive -> published)
p50/p99, its peak resident memory (the kernel's high-water mark), the frames the full queues
dropped and the clients closed, and what each reading client received.

Usage: scripts/foxglove-benchmark.py DATA [--resolution 0.2] [--max-range 30] [--rate 10]
                                     [--clients 10] [--runs 3]
Run as root it runs each server inside `unshare -n` (loopback only). Binaries from
<build>/bin (DENSEMAP_BUILD_DIR, default build); tests/foxglove/node_modules from `npm ci`.
"""

import argparse
import glob
import json
import os
import re
import statistics
import subprocess
import sys

from bench_stats import cpu_model, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))


def run(args, clients):
    env = dict(os.environ, BENCH="0", FOXGLOVE=str(clients),
               DENSEMAP_BIN=os.path.join(BUILD, "bin"))
    command = [os.path.join(ROOT, "scripts", "realtime-check.sh"), args.data,
               str(args.resolution), str(args.max_range), str(args.rate)]
    if os.geteuid() == 0:
        command = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh"] + command
    out = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True, check=True).stdout
    status = re.search(r"integrated (\d+), dropped (\d+), rejected \d+; latency p50 ([\d.]+) ms "
                       r"p99 ([\d.]+) ms", out)
    hwm = re.search(r"high-water mark (\d+) KiB", out)
    cpu = re.search(r"CPU s: ([\d.]+)", out)
    outputs = re.search(r"outputs in (\S+)", out).group(1)
    r = {"integrated": int(status.group(1)), "dropped": int(status.group(2)),
         "p50": float(status.group(3)), "p99": float(status.group(4)),
         "rss_mib": int(hwm.group(1)) / 1024.0, "cpu_s": float(cpu.group(1)), "frames_dropped": 0, "closed": 0, "mb": []}
    fox = re.search(r"foxglove: (\d+) clients; (\d+) frames dropped for full send queues, (\d+) "
                    r"clients closed", out)
    if fox:
        r["frames_dropped"] = int(fox.group(2))
        r["closed"] = int(fox.group(3))
    for path in sorted(glob.glob(os.path.join(outputs, "foxglove-*.json"))):
        with open(path) as f:
            counts = json.load(f)
        total = sum(counts["bytes"].values())
        if total > 0:
            r["mb"].append(total / 1e6)
    return r


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("data")
    p.add_argument("--resolution", type=float, default=0.2)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--clients", type=int, default=10)
    p.add_argument("--runs", type=int, default=3)
    args = p.parse_args()
    results = {0: [], args.clients: []}
    for i in range(args.runs):
        for clients in (0, args.clients):
            r = run(args, clients)
            results[clients].append(r)
            print(f"run {i + 1}, {clients} clients: {r}", file=sys.stderr)
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; {os.path.basename(args.data.rstrip('/'))} "
          f"at {args.resolution} m / {args.max_range} m, {args.rate:g} Hz; {args.runs} runs alternated "
          f"(median, min .. max)\n")
    print("| Foxglove clients | scans integrated (dropped) | server p50 ms | server p99 ms | "
          "server CPU s | peak RSS MiB | frames dropped / clients closed | "
          "MB received per reading client |")
    print("|---|---|---|---|---|---|---|---|")
    for clients, rs in results.items():
        label = "endpoint off" if clients == 0 else f"{clients} (1 never reads)"
        integrated = f"{min(r['integrated'] for r in rs)}-{max(r['integrated'] for r in rs)} " \
                     f"({max(r['dropped'] for r in rs)} at most)"
        mb = [m for r in rs for m in r["mb"]]
        print(f"| {label} | {integrated} | {spread([r['p50'] for r in rs], '{:.1f}')} | "
              f"{spread([r['p99'] for r in rs], '{:.1f}')} | {spread([r['cpu_s'] for r in rs], '{:.1f}')} | "
              f"{spread([r['rss_mib'] for r in rs], '{:.0f}')} | "
              f"{max(r['frames_dropped'] for r in rs)} / {max(r['closed'] for r in rs)} | "
              f"{spread(mb, '{:.0f}') if mb else '-'} |")
    base, loaded = results[0], results[args.clients]
    ratio = statistics.median(r["p50"] for r in loaded) / statistics.median(r["p50"] for r in base)
    rss = statistics.median(r["rss_mib"] for r in loaded) - statistics.median(r["rss_mib"] for r in base)
    print(f"\nServer p50 with clients / without: {ratio:.2f}; peak RSS {rss:+.0f} MiB.")


if __name__ == "__main__":
    main()
