#!/usr/bin/python3
"""Pose corrections on one dataset, through a densemap-server with a history: streams the scans
(each waits for the one before to be integrated), then corrects the poses of the last
--corrected scans (moved 0.2 m and turned 0.02 rad, as a loop closure moves them) while a client
queries --points points near the path without pause. Prints a markdown table for
docs/benchmarks.md: the re-integration's time a scan and in all (the server's clock, from the
correction's arrival to the swap), the point queries' p50 / p99 in the 2 s before the
correction and while it ran, and the queried points whose state or
log-odds differs from a second server's fed the corrected scans from scratch (0: exact; the
script exits non-zero otherwise).

Usage: unshare -n sh -c 'ip link set lo up && exec scripts/correction-benchmark.py DATA
           [--first 20 --limit 80] [--resolution 0.1] [--max-range 30] [--corrected 40]
           [--points 5000] [--runs 3] [--domain 230]'
The servers and module are taken from <build>/bin and <build>/python (DENSEMAP_BUILD_DIR,
default build); the reference server runs on --domain + 1. Every socket is on loopback.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time

from bench_stats import cpu_model, percentile, spread

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))
sys.path.insert(0, os.path.join(BUILD, "python"))

import numpy as np  # noqa: E402

import densemap  # noqa: E402


def sensor_scans(data, first, limit):
    """(points in the sensor frame, world-from-sensor 4x4) of each scan."""
    reader = densemap.read_scans(data)
    end = len(reader) if limit == 0 else min(len(reader), first + limit)
    out = []
    for i in range(first, end):
        scan = reader[i]
        pose = np.asarray(scan.pose, dtype=np.float64)
        points = np.asarray(scan.points, dtype=np.float64)
        if scan.frame == "world":
            points = (points - pose[:3, 3]) @ pose[:3, :3]
        out.append((np.ascontiguousarray(points, dtype=np.float32), pose))
    return out


def loop_closure():
    """The correction every corrected pose gets: 0.2 m along x, 0.1 m along y, 0.02 rad of yaw."""
    c, s = np.cos(0.02), np.sin(0.02)
    fix = np.eye(4)
    fix[:2, :2] = [[c, -s], [s, c]]
    fix[:3, 3] = [0.2, 0.1, 0.0]
    return fix


def wait_for(client, done, what, timeout=600.0):
    deadline = time.monotonic() + timeout
    while True:
        status = client.status()
        if done(status):
            return status
        if time.monotonic() > deadline:
            sys.exit(f"correction-benchmark: {what} within {timeout:.0f} s")
        time.sleep(0.02)


class Server:
    """A densemap-server on `domain` (loopback) in a directory of its own, with a history."""

    def __init__(self, args, domain):
        self.work = tempfile.mkdtemp(prefix="densemap-correction-")
        config = os.path.join(self.work, "server.textproto")
        with open(config, "w") as f:
            f.write(f'dds {{ domain_id: {domain} network_interface: "lo" }}\n'
                    f'snapshot {{ path: "{self.work}/map.dmap" }}\n'
                    f'map {{ resolution_m: {args.resolution} max_range_m: {args.max_range} }}\n'
                    f'pipeline {{ threads: {args.threads} }}\n'
                    f'history {{ enabled: true directory: "{self.work}/history" '
                    'checkpoint_every: 20 }\n')
        self.log = open(os.path.join(self.work, "server.log"), "w")
        self.process = subprocess.Popen(
            [os.path.join(BUILD, "bin", "densemap-server"), "--config", config],
            stdout=self.log, stderr=self.log)

    def close(self):
        self.process.terminate()
        self.process.wait(timeout=60)
        self.log.close()


def stream(client, scans, stamps):
    """Publishes each scan and waits for it to be integrated."""
    for i, (points, pose) in enumerate(scans):
        client.publish_scan(points, pose, sensor_id="robot", seq=i + 1, stamp_ns=stamps[i])
        wait_for(client, lambda s, n=i + 1: s["integrated"] >= n, f"scan {i + 1}")


def one_run(args, scans, queries):
    stamps = [(i + 1) * 100_000_000 for i in range(len(scans))]
    fix = loop_closure()
    first = len(scans) - args.corrected
    corrected = [(p, fix @ T if i >= first else T) for i, (p, T) in enumerate(scans)]
    server = Server(args, args.domain)
    try:
        with densemap.Client(domain_id=args.domain, timeout=30.0) as client:
            client.wait_for_server()
            stream(client, scans, stamps)
            latencies, stop = [], threading.Event()

            def query():
                with densemap.Client(domain_id=args.domain, timeout=30.0) as q:
                    q.wait_for_server()
                    while not stop.is_set():
                        t0 = time.monotonic()
                        q.query_points(queries)
                        latencies.append((t0, (time.monotonic() - t0) * 1e3))

            thread = threading.Thread(target=query)
            thread.start()
            time.sleep(2.0)
            start = time.monotonic()
            client.publish_pose_correction(
                "robot", [(stamps[i], corrected[i][1]) for i in range(first, len(scans))])
            status = wait_for(client, lambda s: s["history"]["reintegrations"] >= 1,
                              "the re-integration")
            stop.set()
            thread.join()
            _, states, log_odds = client.query_points(queries)
    finally:
        server.close()
    # The same scans with the corrected poses from scratch, through the same path.
    reference = Server(args, args.domain + 1)
    try:
        with densemap.Client(domain_id=args.domain + 1, timeout=30.0) as client:
            client.wait_for_server()
            stream(client, corrected, stamps)
            _, want_states, want = client.query_points(queries)
    finally:
        reference.close()
    differ = int(np.sum((states != want_states) |
                        ~((log_odds == want) | (np.isnan(log_odds) & np.isnan(want)))))
    history = status["history"]
    # The server's own time for it (the status comes once a second): from the correction's
    # arrival to the swap.
    wall_s = history["last_ms_per_scan"] * history["reintegration_total"] / 1e3
    end = start + wall_s
    return {
        "scans": history["reintegration_total"],
        "ms_a_scan": history["last_ms_per_scan"],
        "wall_s": wall_s,
        "before": [ms for t, ms in latencies if start - 2.0 <= t < start],
        "during": [ms for t, ms in latencies if start <= t < end],
        "differ": differ,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data")
    parser.add_argument("--first", type=int, default=20)
    parser.add_argument("--limit", type=int, default=80)
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--max-range", type=float, default=30.0)
    parser.add_argument("--corrected", type=int, default=40)
    parser.add_argument("--points", type=int, default=5000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--domain", type=int, default=230)
    args = parser.parse_args()
    scans = sensor_scans(args.data, args.first, args.limit)
    if len(scans) <= args.corrected:
        sys.exit("correction-benchmark: --corrected must be below the number of scans")
    rng = np.random.default_rng(7)
    picks = []
    for points, pose in scans[:: max(1, len(scans) // 10)]:
        chosen = points[rng.integers(0, len(points), args.points // 10)].astype(np.float64)
        picks.append(chosen @ pose[:3, :3].T + pose[:3, 3])
    queries = np.ascontiguousarray(np.concatenate(picks), dtype=np.float32)
    runs = [one_run(args, scans, queries) for _ in range(args.runs)]
    print(f"{len(scans)} scans of {args.data}, {args.resolution} m / {args.max_range} m, the last "
          f"{args.corrected} corrected; {args.threads} threads; {len(queries)} points a query; "
          f"{cpu_model()}, {os.cpu_count()} CPUs; median (min .. max) of {args.runs} runs\n")
    print("| scans re-integrated | ms a scan | re-integration s | queries p50 / p99 ms before | "
          "queries p50 / p99 ms during | queries during | points differing from scratch |")
    print("|---|---|---|---|---|---|---|")

    def pct(key, q):
        return spread([percentile(r[key], q) for r in runs], "{:.2f}")

    print(f"| {spread([r['scans'] for r in runs], '{:.0f}')} "
          f"| {spread([r['ms_a_scan'] for r in runs], '{:.1f}')} "
          f"| {spread([r['wall_s'] for r in runs], '{:.2f}')} "
          f"| {pct('before', 50)} / {pct('before', 99)} "
          f"| {pct('during', 50)} / {pct('during', 99)} "
          f"| {spread([len(r['during']) for r in runs], '{:.0f}')} "
          f"| {max(r['differ'] for r in runs)} |")
    if any(r["differ"] for r in runs):
        sys.exit("correction-benchmark: the corrected map differs from the map built from scratch")


if __name__ == "__main__":
    main()
