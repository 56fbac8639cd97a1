"""Statistics and machine facts the benchmark scripts report, defined once."""

import math
import platform
import statistics


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
