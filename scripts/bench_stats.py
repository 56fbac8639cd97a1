"""Statistics the benchmark scripts report, defined once."""

import math


def percentile(values, q):
    """The nearest-rank percentile (q in 0..100), as densemap-bench reports it."""
    ordered = sorted(values)
    rank = max(1, int(math.ceil(q / 100.0 * len(ordered))))
    return ordered[rank - 1]
