"""Statistics and machine facts the benchmark scripts report, defined once."""

import math
import os
import platform
import re
import statistics
import subprocess


def percentile(values, q):
    """The nearest-rank percentile (q in 0..100), as densemap-bench reports it."""
    ordered = sorted(values)
    rank = max(1, int(math.ceil(q / 100.0 * len(ordered))))
    return ordered[rank - 1]


def cpu_model():
    """The CPU's model name from /proc/cpuinfo (the machine's architecture where it has none)."""
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.machine()


def spread(values, fmt="{:.1f}"):
    """'median (min .. max)' of several runs, each formatted with fmt."""
    return (fmt.format(statistics.median(values)) + " (" + fmt.format(min(values)) + " .. " +
            fmt.format(max(values)) + ")")


def realtime_check(root, data, resolution, max_range, rate, env):
    """One scripts/realtime-check.sh run (inside `unshare -n` when root) with this environment:
    (integrated, dropped, server p50 ms, p99 ms, CPU s, minor page faults, the replay client's
    CPU s)."""
    command = [os.path.join(root, "scripts", "realtime-check.sh"), data, str(resolution),
               str(max_range), str(rate)]
    if os.geteuid() == 0:
        command = ["unshare", "-n", "sh", "-c", 'ip link set lo up && exec "$@"', "sh"] + command
    out = subprocess.run(command, env=env, cwd=root, capture_output=True, text=True,
                         check=True).stdout
    status = re.search(r"integrated (\d+), dropped (\d+), rejected \d+; latency p50 ([\d.]+) ms "
                       r"p99 ([\d.]+) ms", out)
    usage = re.search(r"minor page faults: (\d+), CPU s: ([\d.]+)", out)
    sender = re.search(r"replay client CPU s: ([\d.]+)", out)
    return (int(status.group(1)), int(status.group(2)), float(status.group(3)),
            float(status.group(4)), float(usage.group(2)), int(usage.group(1)),
            float(sender.group(1)))


def bench_lane(out, lane):
    """A densemap-bench lane's p50 and p99 ms a scan, from its table on stdout."""
    row = re.search(rf"^{re.escape(lane)}\s+\S+\s+\S+\s+\d+\s+\d+\s+\d+\s+([\d.]+)\s+([\d.]+)",
                    out, re.M)
    if row is None:
        raise RuntimeError(f"densemap-bench printed no row for {lane}")
    return float(row.group(1)), float(row.group(2))


def dense_rows(path):
    """The first table of scripts/dense-map-benchmark.sh's tables.md with one method (METHODS):
    {row: its 'AUC [+- spread] / MSE' cell, bold marks removed}."""
    rows = {}
    with open(path) as f:
        for line in f:
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) == 2 and " / " in cells[1] and cells[0] not in rows:
                rows[cells[0]] = cells[1].replace("**", "")
    return rows
