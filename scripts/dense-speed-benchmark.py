#!/usr/bin/python3
"""A dense map setting against the default (akimap_rays), or this build against another: what
it saves and what it costs. Prints three markdown tables for docs/benchmarks.md (without
--compare, two: the builds' bench runs alternated, then the server):

1. densemap-bench on DATA, the default and the setting (--compare, a kernel setting such as
   free_bundle_levels=0) as lanes of the same run, taking turns, --runs runs: p50 / p99 ms a
   scan and one stage's mean (--stage: free by default);
2. with --baseline-bin DIR (the binaries of another build): scripts/realtime-check.sh at --rate
   Hz (the server with the replay client on the same cores), that build's and this one's
   alternated, --runs runs: scans integrated, server p50 / p99, the server's and the replay
   client's CPU ms a scan;
3. accuracy: scripts/dense-map-benchmark.sh (akimap_rays, 3 seeds, BALM's 0.2 m row left out)
   with the default and with the setting, plus DATA's hold-out at --resolution / --max-range
   (densemap-eval, 40 scans).
Without --compare (--baseline-bin then required), table 1 has the baseline build's and this
build's densemap-bench runs, alternated, and their evidence digests: equal digests are the
same map bit for bit, so no accuracy table is needed; different ones fail the script.

Usage: scripts/dense-speed-benchmark.py DATA [--compare NAME=VALUE] [--baseline-bin DIR]
           [--resolution 0.1] [--max-range 30] [--rate 10] [--runs 3] [--accuracy-data DIR]
           [--stage samples|kernels|occupied|free|apply]
DATA: a dataset densemap-bench reads. --accuracy-data: the dense-map benchmark's real data
(default $DENSEMAP_DATA_DIR, else ../shared/data). Run as root it runs each server inside
`unshare -n` (loopback only). Binaries from <build>/bin (DENSEMAP_BUILD_DIR, default build).
"""

import argparse
import os
import re
import subprocess
import tempfile

from bench_stats import bench_lane, cpu_model, dense_rows, realtime_check, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))
BIN = os.path.join(BUILD, "bin")
# densemap-bench's dense stages, in the order it prints their means.
STAGES = ["samples", "kernels", "occupied", "free", "apply"]


def lane(setting):
    return "akimap_rays" if setting is None else f"akimap_rays@set={setting}"


def label(setting):
    return "default" if setting is None else setting


def bench(args, settings, bin_dir=BIN):
    """One densemap-bench run, every setting a lane: {setting: (p50, p99, the stage's ms,
    evidence digest)}."""
    out = subprocess.run(
        [os.path.join(bin_dir, "densemap-bench"), "--data", args.data, "--resolution",
         str(args.resolution), "--max-range", str(args.max_range), "--threads", "2",
         "--methods", ",".join(lane(lod) for lod in settings)],
        capture_output=True, text=True, check=True).stdout
    result = {}
    for setting in settings:
        name = re.escape(lane(setting))
        stages = re.search(rf"^{name}\s+kernel\s+.*?([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+) ([\d.]+)"
                           r"\s+\(dense", out, re.M)
        digest = re.search(rf"^{name}/kernel:.*evidence digest ([0-9a-f]+)", out, re.M)
        result[setting] = bench_lane(out, lane(setting)) + (
            float(stages.group(STAGES.index(args.stage) + 1)), digest.group(1))
    return result


def compare_builds(args):
    """Table 1 without --compare: the baseline build's and this build's bench runs, alternated;
    exits with an error when their maps differ."""
    builds = [("baseline build", args.baseline_bin), ("this build", BIN)]
    runs = {name: [] for name, _ in builds}
    for _ in range(args.runs):
        for name, bin_dir in builds:
            runs[name].append(bench(args, [None], bin_dir)[None])
    print("densemap-bench, the builds' runs alternated:\n")
    print(f"| build | bench p50 ms | bench p99 ms | {args.stage} stage mean ms | p50 / baseline "
          "(run by run) | evidence digest |")
    print("|---|---|---|---|---|---|")
    base = runs["baseline build"]
    for name, _ in builds:
        r = runs[name]
        ratio = [x[0] / b[0] for x, b in zip(r, base)]
        print(f"| {name} | {spread([x[0] for x in r])} | {spread([x[1] for x in r])} | "
              f"{spread([x[2] for x in r])} | {spread(ratio, '{:.2f}')} | "
              f"{', '.join(sorted({x[3] for x in r}))} |")
    digests = {x[3] for r in runs.values() for x in r}
    if len(digests) != 1:
        raise SystemExit(f"the builds' maps differ (evidence digests {sorted(digests)}): "
                         "compare their accuracy with --compare instead")


def server(args, bin_dir):
    """One scripts/realtime-check.sh run with these binaries: (integrated, dropped, p50, p99,
    CPU s, the replay client's CPU s)."""
    env = dict(os.environ, BENCH="0", KIND="akimap_rays", DENSEMAP_BIN=bin_dir)
    run = realtime_check(ROOT, args.data, args.resolution, args.max_range, args.rate, env)
    return run[:5] + run[6:]


def accuracy(args, setting, work):
    """{row: 'AUC / MSE'} of akimap_rays with this setting (None: the default)."""
    out_dir = os.path.join(work, "accuracy-" + re.sub(r"[^A-Za-z0-9_.-]", "_", label(setting)))
    env = dict(os.environ, METHODS="akimap_rays", BENCH_SKIP_BALM="1", DENSEMAP_BUILD_DIR=BUILD,
               EVAL_ARGS="" if setting is None else f"--kernel-set {setting}")
    subprocess.run([os.path.join(ROOT, "scripts", "dense-map-benchmark.sh"), out_dir, "3",
                    args.accuracy_data], env=env, cwd=ROOT, capture_output=True, check=True)
    rows = dense_rows(os.path.join(out_dir, "tables.md"))
    extra = [] if setting is None else ["--kernel-set", setting]
    out = subprocess.run(
        [os.path.join(BIN, "densemap-eval"), "--method", "akimap_rays", "--threads", "2",
         "--data", args.data, "--first", "0", "--limit", "40", "--protocol", "holdout",
         "--resolution", str(args.resolution), "--max-range", str(args.max_range), "--runs", "1"]
        + extra, capture_output=True, text=True, check=True).stdout
    m = re.search(r"^akimap_rays\s+([\d.]+)\+-[\d.]+\s+([\d.]+)", out, re.M)
    rows[f"holdout {os.path.basename(os.path.normpath(args.data))} {args.resolution:g} / "
         f"{args.max_range:g} m (40 scans)"] = f"{float(m.group(1)):.4f} / {float(m.group(2)):.4f}"
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("--compare", help="a kernel setting NAME=VALUE (without it: the builds)")
    p.add_argument("--baseline-bin", help="another build's bin directory, for the server runs")
    p.add_argument("--resolution", type=float, default=0.1)
    p.add_argument("--max-range", type=float, default=30.0)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--stage", choices=STAGES, default="free",
                   help="the dense stage whose mean the bench table shows")
    p.add_argument("--accuracy-data",
                   default=os.environ.get("DENSEMAP_DATA_DIR", os.path.join(ROOT, "..", "shared",
                                                                            "data")))
    args = p.parse_args()
    if args.compare is None and args.baseline_bin is None:
        p.error("give --compare NAME=VALUE, --baseline-bin DIR, or both")
    settings = [args.compare, None]
    print(f"Machine: {cpu_model()}, {os.cpu_count()} vCPUs; "
          f"{os.path.basename(os.path.normpath(args.data))} at {args.resolution:g} m / "
          f"{args.max_range:g} m, 2 threads; {args.runs} runs (median, min .. max)\n")

    if args.compare is None:
        compare_builds(args)
    else:
        benches = [bench(args, settings) for _ in range(args.runs)]
        print("densemap-bench, both lanes of the same run:\n")
        print(f"| akimap_rays | bench p50 ms | bench p99 ms | {args.stage} stage mean ms | p50 / "
              f"{args.compare} |")
        print("|---|---|---|---|---|")
        for setting in settings:
            ratio = [b[setting][0] / b[args.compare][0] for b in benches]
            print(f"| {label(setting)} | {spread([b[setting][0] for b in benches])} | "
                  f"{spread([b[setting][1] for b in benches])} | "
                  f"{spread([b[setting][2] for b in benches])} | {spread(ratio, '{:.2f}')} |")

    if args.baseline_bin:
        builds = [("baseline build", args.baseline_bin), ("this build", BIN)]
        servers = {name: [] for name, _ in builds}
        for _ in range(args.runs):
            for name, bin_dir in builds:
                servers[name].append(server(args, bin_dir))
        print(f"\nThe server at {args.rate:g} Hz (scripts/realtime-check.sh, KIND=akimap_rays), "
              "the builds alternated:\n")
        print("| build | scans integrated (per run) | server p50 ms | server p99 ms | "
              "server CPU ms a received scan | replay CPU ms a scan |")
        print("|---|---|---|---|---|---|")
        for name, _ in builds:
            runs = servers[name]
            received = [r[0] + r[1] for r in runs]
            print(f"| {name} | {', '.join(f'{r[0]}/{n}' for r, n in zip(runs, received))} | "
                  f"{spread([r[2] for r in runs])} | {spread([r[3] for r in runs])} | "
                  f"{spread([1000.0 * r[4] / n for r, n in zip(runs, received)], '{:.0f}')} | "
                  f"{spread([1000.0 * r[5] / n for r, n in zip(runs, received)], '{:.1f}')} |")

    if args.compare is None:
        return
    with tempfile.TemporaryDirectory(prefix="densemap-speed-") as work:
        scores = {setting: accuracy(args, setting, work) for setting in settings}
    print("\nAccuracy, akimap_rays, AUC / MSE (scripts/dense-map-benchmark.sh rows: mean of 3 "
          "seeds):\n")
    print("| case | " + " | ".join(label(s) for s in settings) + " |")
    print("|---|" + "---|" * len(settings))
    for row in scores[None]:
        print(f"| {row} | " + " | ".join(scores[s].get(row, "-") for s in settings) + " |")


if __name__ == "__main__":
    main()
