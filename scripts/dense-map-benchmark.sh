#!/usr/bin/env bash
# The dense maps' accuracy benchmark, reproducible; every method scored by
# the same command on each dataset, with 2 worker threads:
#   1. oracle protocol: the structured and unstructured scenes simulated with dense-oracle labels
#      (12 scans x 3,500 points from 4 stations, 8 m range), at 0.1 m and 0.05 m;
#   1b. oracle protocol at long range: the outdoor scene seen by a simulated 64-beam sensor
#      (12 scans, full hdl64 scans to 80 m, 0.2 m), without akimap (its free samples every
#      0.5 m of 80 m rays take minutes a scan); the only row where rays pass 15 m, so the one
#      that judges changes to far free space;
#   2. hold-out protocol on real data, where DATA (default ../shared/data) holds it: la3dm's
#      two scenes (0.1 m, 8 m), the AKIMap authors' sample (0.1 m) and BALM scans 20-59
#      (0.2 m, 15 m; slow: AKIMap takes about 75 s per scan on 2 cores, 50 min for the 40;
#      BALM_SCANS=N scores scans 20..19+N).
# Methods: akimap, bgk, bgkl, raycast and akimap_rays. Writes per case a table (.txt), JSON,
# ROC curves and reliability diagrams (SVG + CSV) into OUT_DIR, and OUT_DIR/summary.md.
# Usage: scripts/dense-map-benchmark.sh OUT_DIR [RUNS [DATA]]   (after scripts/build.sh)
#   RUNS: seeds per case (default 3: every table prints the mean and spread), except BALM's
#   (BALM_RUNS, default 1: slow); BENCH_SKIP_BALM=1 leaves BALM out. METHODS=a,b scores only
#   those (e.g. METHODS=akimap_rays with EVAL_ARGS="--kernel-set NAME=VALUE" to judge a setting
#   on every row in a few minutes); EVAL_ARGS goes to every densemap-eval call.
balm_scans=${BALM_SCANS:-40}
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: scripts/dense-map-benchmark.sh OUT_DIR [RUNS [DATA]]}
runs=${2:-3}
data=${3:-${DENSEMAP_DATA_DIR:-../shared/data}}
bin=${DENSEMAP_BUILD_DIR:-build}/bin
methods=${METHODS:-akimap,bgk,bgkl,raycast,akimap_rays}
read -r -a eval_args <<<"${EVAL_ARGS:-}"
mkdir -p "$out"
: >"$out/summary.md"
score() {  # NAME ARGS...: one densemap-eval run, its table appended to the summary
  local name=$1
  shift
  echo "dense-map-benchmark: $name"
  "$bin/densemap-eval" --method "$methods" --threads 2 --json "$out/$name.json" \
    --roc "$out/roc_$name" --reliability "$out/reliability_$name" "${eval_args[@]}" "$@" |
    tee "$out/$name.txt"
  { echo "### $name"; echo '```'; cat "$out/$name.txt"; echo '```'; } >>"$out/summary.md"
}
for scene in structured unstructured; do
  if [ ! -f "$out/$scene/oracle_0.05.bt" ]; then
    echo "dense-map-benchmark: simulating $scene"
    "$bin/densemap-sim" --out "$out/$scene" --scene "$scene" --sensor os0-64 --columns 512 \
      --scans 12 --points-per-scan 3500 --max-range 8 --oracle-factor 2 \
      --oracle-resolutions 0.1,0.05 --gt-resolution 0.05
  fi
  for res in 0.1 0.05; do
    score "oracle_${scene}_$res" --data "$out/$scene" --protocol oracle --resolution "$res" \
      --max-range 8 --runs "$runs" --slice "$out/slice_${scene}_$res" --slice-z 1.0
  done
done
all_methods=$methods
methods=$(tr ',' '\n' <<<"$methods" | { grep -vx akimap || true; } | paste -sd, -)
if [ -n "$methods" ]; then
  if [ ! -f "$out/outdoor_hdl64/oracle_0.2.bt" ]; then
    echo "dense-map-benchmark: simulating outdoor_hdl64"
    "$bin/densemap-sim" --out "$out/outdoor_hdl64" --scene outdoor --sensor hdl64 --scans 12 \
      --seed 3 --oracle-factor 2 --oracle-resolutions 0.2 --gt-resolution 0.2
  fi
  score oracle_outdoor_hdl64_0.2 --data "$out/outdoor_hdl64" --protocol oracle \
    --resolution 0.2 --max-range 80 --runs "$runs"
fi
methods=$all_methods
for scene in structured unstructured; do
  if [ -d "$data/la3dm/sim_$scene" ]; then
    score "holdout_la3dm_$scene" --data "$data/la3dm/sim_$scene" --protocol holdout \
      --resolution 0.1 --max-range 8 --runs "$runs"
  else
    echo "dense-map-benchmark: $data/la3dm/sim_$scene is absent: skipped"
  fi
done
if [ -f "$data/akimap-sample/akimap_sample.graph" ]; then
  score holdout_akimap_sample --data "$data/akimap-sample/akimap_sample.graph" \
    --protocol holdout --resolution 0.1 --runs "$runs"
else
  echo "dense-map-benchmark: $data/akimap-sample is absent: skipped"
fi
if [ -d "$data/balm-realworld" ] && [ -z "${BENCH_SKIP_BALM:-}" ]; then
  score "holdout_balm_20-$((19 + balm_scans))" --data "$data/balm-realworld" --first 0 \
    --limit "$balm_scans" \
    --protocol holdout --resolution 0.2 --max-range 15 --runs "${BALM_RUNS:-1}"
else
  echo "dense-map-benchmark: BALM skipped (absent, or BENCH_SKIP_BALM set)"
fi
# The tables of docs/benchmarks.md: per case, each method's AUC (+- the seeds' spread) / MSE,
# the row's best AUC and best MSE in bold (ties within the spread both bold); then the expected
# calibration error per case, the best in bold.
PY=/usr/bin/python3
[ -x "$PY" ] || PY=python3
"$PY" - "$out" "$all_methods" >"$out/tables.md" <<'PYTABLE'
import json, os, sys
out, methods = sys.argv[1], sys.argv[2].split(",")
cases = [c for c in ["oracle_structured_0.1", "oracle_structured_0.05",
                     "oracle_unstructured_0.1", "oracle_unstructured_0.05",
                     "oracle_outdoor_hdl64_0.2", "holdout_la3dm_structured",
                     "holdout_la3dm_unstructured", "holdout_akimap_sample"]
         if os.path.exists(f"{out}/{c}.json")]
cases += sorted(c[:-5] for c in os.listdir(out) if c.startswith("holdout_balm") and c.endswith(".json"))
def load(case):
    return {r["method"]: r for r in json.load(open(f"{out}/{case}.json"))["results"]}
def row(case, cell, best):
    r = load(case)
    return f"| {case.replace('_', ' ')} | " + " | ".join(cell(r[m], best(r, m)) if m in r else "-" for m in methods) + " |"
header = "| case | " + " | ".join(methods) + " |\n|---" * 1 + "|---" * len(methods) + "|"
print("AUC (+- spread over seeds) / MSE; bold: the row's best (AUC ties within the spread).\n")
print(header)
for case in cases:
    r = load(case)
    top_auc = max(v["auc"] for v in r.values())
    spread = max([v["auc_sd"] for v in r.values() if v["auc"] == top_auc] + [0.0])
    low_mse = min(v["mse"] for v in r.values())
    def cell(v, _):
        auc = f"{v['auc']:.4f}" + (f" +- {v['auc_sd']:.4f}" if v["auc_sd"] >= 0.00005 else "")
        if top_auc - v["auc"] <= max(spread, v["auc_sd"]): auc = f"**{auc}**"
        mse = f"{v['mse']:.4f}"
        if v["mse"] == low_mse: mse = f"**{mse}**"
        return f"{auc} / {mse}"
    print(row(case, cell, lambda r, m: None))
print("\nExpected calibration error; bold: the row's best.\n")
print(header)
for case in cases:
    r = load(case)
    low = min(v["ece"] for v in r.values())
    print(row(case, lambda v, _: f"**{v['ece']:.3f}**" if v["ece"] == low else f"{v['ece']:.3f}", lambda r, m: None))
PYTABLE
cat "$out/tables.md"
echo "dense-map-benchmark: wrote $out/summary.md and $out/tables.md"
