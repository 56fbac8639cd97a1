#!/usr/bin/python3
"""akimap_rays' accuracy with each of several settings against its defaults, on every row of
scripts/dense-map-benchmark.sh (3 seeds; BALM's row with one run of 40 scans where the data
has it). Prints a markdown table for docs/benchmarks.md: the defaults' AUC / MSE, then per
setting each row's AUC change and MSE change in percent, marked where the row loses more than
0.002 AUC or 5% MSE (the dense map's accuracy gate).

Usage: scripts/dense-setting-sweep.py SETTING [SETTING ...] [--runs 3] [--data DIR]
SETTING: NAME=VALUE, or several joined by ':' (hit_weight=0.9:occupied_weight=0.7).
--data: the benchmark's real data (default $DENSEMAP_DATA_DIR, else ../shared/data).
Binaries from <build>/bin (DENSEMAP_BUILD_DIR, default build). About 20 s a setting here.
"""

import argparse
import os
import subprocess
import tempfile

from bench_stats import dense_rows

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD = os.path.join(ROOT, os.environ.get("DENSEMAP_BUILD_DIR", "build"))


def scores(args, setting, work):
    """{row: (AUC, MSE)} of akimap_rays with this setting (None: the defaults)."""
    out_dir = os.path.join(work, "defaults" if setting is None else setting.replace("=", "_"))
    extra = [] if setting is None else [f"--kernel-set {s}" for s in setting.split(":")]
    env = dict(os.environ, METHODS="akimap_rays", DENSEMAP_BUILD_DIR=BUILD,
               EVAL_ARGS=" ".join(extra))
    subprocess.run([os.path.join(ROOT, "scripts", "dense-map-benchmark.sh"), out_dir,
                    str(args.runs), args.data], env=env, cwd=ROOT, capture_output=True,
                   check=True)
    rows = {}
    for row, cell in dense_rows(os.path.join(out_dir, "tables.md")).items():
        auc, mse = cell.split(" / ")
        rows[row] = (float(auc.split("+-")[0]), float(mse))
    return rows


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("settings", nargs="+")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--data", default=os.environ.get(
        "DENSEMAP_DATA_DIR", os.path.join(ROOT, "..", "shared", "data")))
    args = p.parse_args()
    for setting in args.settings:
        if any("=" not in part for part in setting.split(":")):
            p.error(f"'{setting}': expected NAME=VALUE[:NAME=VALUE...]")
    with tempfile.TemporaryDirectory(prefix="densemap-sweep-") as work:
        base = scores(args, None, work)
        swept = {s: scores(args, s, work) for s in args.settings}
    rows = list(base)
    print("| akimap_rays | " + " | ".join(rows) + " |")
    print("|---|" + "---|" * len(rows))
    print("| defaults (AUC / MSE) | " +
          " | ".join(f"{base[r][0]:.4f} / {base[r][1]:.4f}" for r in rows) + " |")
    for setting in args.settings:
        cells = []
        for r in rows:
            if r not in swept[setting]:
                cells.append("-")
                continue
            auc, mse = swept[setting][r]
            loses = base[r][0] - auc > 0.002 or mse > 1.05 * base[r][1]
            cell = f"{auc - base[r][0]:+.4f} / {100.0 * (mse / base[r][1] - 1.0):+.0f}%"
            cells.append(f"**{cell}**" if loses else cell)
        print(f"| {setting.replace(':', ' ')} | " + " | ".join(cells) + " |")
    print("\nAUC change / MSE change against the defaults; bold: the row loses more than 0.002 "
          "AUC or 5% MSE.")


if __name__ == "__main__":
    main()
