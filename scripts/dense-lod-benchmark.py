#!/usr/bin/python3
"""The dense map's level of detail by range (akimap_rays, map.dense_lod_range_m): what it saves
and what it costs, each range against off in the same runs. Prints three markdown tables for
docs/benchmarks.md:

1. densemap-bench on DATA (every setting a lane of the same run, taking turns), --runs runs:
   p50 / p99 ms a scan and the free stage's mean;
2. scripts/realtime-check.sh at --rate Hz (the server, the replay client on the same cores),
   off and each range alternated, --runs runs: scans integrated, server p50 / p99, CPU s;
3. accuracy: scripts/dense-map-benchmark.sh (akimap_rays, 3 seeds, BALM's 0.2 m row left out)
   per setting, plus DATA's hold-out at --resolution / --max-range (densemap-eval, 40 scans).

Usage: scripts/dense-lod-benchmark.py DATA [--ranges 6] [--resolution 0.1] [--max-range 30]
                                      [--rate 10] [--runs 3] [--accuracy-data DIR]
DATA: a dataset densemap-bench reads (BALM's balm-realworld for the tables in the docs).
--accuracy-data: the dense-map benchmark's real data (default $DENSEMAP_DATA_DIR, else
../shared/data). Run as root it runs each server inside `unshare -n` (loopback only).
Binaries from <build>/bin (DENSEMAP_BUILD_DIR, default build).
"""

import argparse
import os
import re
import statistics
import subprocess
import tempfile

from bench_stats import cpu_model

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))
BIN = os.path.join(BUILD, "bin")


def lane(lod):
    return "akimap_rays" if lod == 0 else f"akimap_rays@set=free_bundle_range_m={lod:g}"


def label(lod):
    return "off" if lod == 0 else f"{lod:g} m"


def bench(args, settings):
    """One densemap-bench run, every setting a lane: {lod: (p50, p99, free ms)}."""
    out = subprocess.run(
        [os.path.join(BIN, "densemap-bench"), "--data", args.data, "--resolution",
         str(args.resolution), "--max-range", str(args.max_range), "--threads", "2",
         "--methods", ",".join(lane(lod) for lod in settings)],
        capture_output=True, text=True, check=True).stdout
    result = {}
    for lod in settings:
        name = re.escape(lane(lod))
        row = re.search(rf"^{name}\s+kernel\s+set\s+\d+\s+\d+\s+\d+\s+([\d.]+)\s+([\d.]+)", out,
                        re.M)
        stages = re.search(rf"^{name}\s+kernel\s+.*?([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+)"
                           r"\s+\(dense", out, re.M)
        result[lod] = (float(row.group(1)), float(row.group(2)), float(stages.group(4)))
    return result


def server(args, lod):
    """One scripts/realtime-check.sh run: (integrated, dropped, p50, p99, CPU s)."""
    env = dict(os.environ, BENCH="0", KIND="akimap_rays", DENSEMAP_BIN=BIN)
    env.pop("DENSE_LOD", None)
    if lod:
        env["DENSE_LOD"] = f"{lod:g}"
    command = [os.path.join(ROOT, "scripts", "realtime-check.sh"), args.data,
               str(args.resolution), str(args.max_range), str(args.rate)]
    if os.geteuid() == 0:
        command = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh"] + command
    out = subprocess.run(command, env=env, cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout
    status = re.search(r"integrated (\d+), dropped (\d+), rejected \d+; latency p50 ([\d.]+) ms "
                       r"p99 ([\d.]+) ms", out)
    cpu = re.search(r"CPU s: ([\d.]+)", out)
    return (int(status.group(1)), int(status.group(2)), float(status.group(3)),
            float(status.group(4)), float(cpu.group(1)))


def accuracy(args, lod, work):
    """{row: 'AUC / MSE'} of akimap_rays with this setting."""
    out_dir = os.path.join(work, f"accuracy-{label(lod).replace(' ', '')}")
    env = dict(os.environ, METHODS="akimap_rays", BENCH_SKIP_BALM="1",
               EVAL_ARGS=f"--kernel-set free_bundle_range_m={lod:g}",
               DENSEMAP_BUILD_DIR=BUILD)
    subprocess.run([os.path.join(ROOT, "scripts", "dense-map-benchmark.sh"), out_dir, "3",
                    args.accuracy_data], env=env, cwd=ROOT, capture_output=True, check=True)
    rows = {}
    with open(os.path.join(out_dir, "tables.md")) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) == 2 and " / " in cells[1] and cells[0] not in rows:
                rows[cells[0]] = cells[1].replace("**", "")
    out = subprocess.run(
        [os.path.join(BIN, "densemap-eval"), "--method", "akimap_rays", "--threads", "2",
         "--data", args.data, "--first", "0", "--limit", "40", "--protocol", "holdout",
         "--resolution", str(args.resolution), "--max-range", str(args.max_range), "--runs", "1",
         "--kernel-set", f"free_bundle_range_m={lod:g}"],
        capture_output=True, text=True, check=True).stdout
    m = re.search(r"^akimap_rays\s+([\d.]+)\+-[\d.]+\s+([\d.]+)", out, re.M)
    rows[f"holdout {os.path.basename(os.path.normpath(args.data))} {args.resolution:g} / "
         f"{args.max_range:g} m (40 scans)"] = f"{float(m.group(1)):.4f} / {float(m.group(2)):.4f}"
    return rows


def spread(values, fmt="{:.1f}"):
    return (fmt.format(statistics.median(values)) + " (" + fmt.format(min(values)) + " .. " +
            fmt.format(max(values)) + ")")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("--ranges", default="6", help="comma-separated ranges, m")
    p.add_argument("--resolution", type=float, default=0.1)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--accuracy-data",
                   default=os.environ.get("DENSEMAP_DATA_DIR", os.path.join(ROOT, "..", "shared",
                                                                            "data")))
    args = p.parse_args()
    settings = [0.0] + [float(r) for r in args.ranges.split(",")]
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; "
          f"{os.path.basename(os.path.normpath(args.data))} at {args.resolution:g} m / "
          f"{args.max_range:g} m, 2 threads; {args.runs} runs (median, min .. max)\n")

    benches = [bench(args, settings) for _ in range(args.runs)]
    print("densemap-bench, every setting a lane of the same run:\n")
    print("| dense_lod_range_m | bench p50 ms | bench p99 ms | free stage mean ms | p50 / off |")
    print("|---|---|---|---|---|")
    for lod in settings:
        ratio = [b[lod][0] / b[0.0][0] for b in benches]
        print(f"| {label(lod)} | {spread([b[lod][0] for b in benches])} | "
              f"{spread([b[lod][1] for b in benches])} | {spread([b[lod][2] for b in benches])} | "
              f"{spread(ratio, '{:.2f}')} |")

    servers = {lod: [] for lod in settings}
    for _ in range(args.runs):
        for lod in settings:
            servers[lod].append(server(args, lod))
    print(f"\nThe server at {args.rate:g} Hz (scripts/realtime-check.sh, KIND=akimap_rays, "
          "DENSE_LOD), alternated:\n")
    print("| dense_lod_range_m | scans integrated (per run) | server p50 ms | server p99 ms | "
          "server CPU ms a received scan |")
    print("|---|---|---|---|---|")
    for lod in settings:
        runs = servers[lod]
        received = [r[0] + r[1] for r in runs]
        print(f"| {label(lod)} | {', '.join(f'{r[0]}/{n}' for r, n in zip(runs, received))} | "
              f"{spread([r[2] for r in runs])} | {spread([r[3] for r in runs])} | "
              f"{spread([1000.0 * r[4] / n for r, n in zip(runs, received)], '{:.0f}')} |")

    with tempfile.TemporaryDirectory(prefix="densemap-lod-") as work:
        scores = {lod: accuracy(args, lod, work) for lod in settings}
    print("\nAccuracy, akimap_rays, AUC / MSE (scripts/dense-map-benchmark.sh rows: mean of 3 "
          "seeds):\n")
    print("| case | " + " | ".join(label(lod) for lod in settings) + " |")
    print("|---|" + "---|" * len(settings))
    for row in scores[0.0]:
        print(f"| {row} | " + " | ".join(scores[lod].get(row, "-") for lod in settings) + " |")


if __name__ == "__main__":
    main()
