// densemap-eval: accuracy of dense maps (AKIMap, BGKOctoMap, BGKOctoMap-L) and of the log-odds
// map on a dataset, by one of two protocols:
// - holdout: each scan's points are split 80/20 (by a seeded hash); maps integrate the 80%; the
//   20% are occupied test points, and one point drawn uniformly on each of their rays (short of
//   the end voxel) is a free test point.
// - oracle (simulated data): maps integrate every point; the test cells are the dense-oracle
//   labels densemap-sim wrote for the same poses (DIR/oracle_<resolution>.bt).
// Rooms: eval_options (the command line), eval_data (scans, the split, oracle labels, slice
// pictures), eval_report (curves, the table, JSON); here: one method's run, and the runs.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/lists.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/raycast/integrator.hpp"
#include "eval_data.hpp"
#include "eval_report.hpp"

namespace densemap::tools {
namespace {

/// Probability of occupancy at a point (std::nullopt where the map does not know).
using Probability = std::function<std::optional<double>(const Point3f&)>;

/// The maps of one method's run (one of the two is made) and the probability they answer.
struct MethodMap {
  std::unique_ptr<kernel::KernelMap> kernel_map;
  std::unique_ptr<OccupancyMap> log_odds_map;
  Probability probability;
};

/// Builds `method`'s map from the scans (in the arena), with progress.
Expected<void> buildMap(const EvalOptions& o, const std::string& method, std::uint64_t run_seed,
                        const std::vector<EvalScan>& scans, tbb::task_arena& arena,
                        Progress& progress, MethodMap& out) {
  if (method == "raycast") {
    out.log_odds_map = std::move(*makeMap(Backend::kGrid, o.resolution));
    out.log_odds_map->setRunner(tbbRunner());
    OccupancyMap& map = *out.log_odds_map;
    Integrator integrator({.max_range_m = o.max_range});
    for (std::size_t i = 0; i < scans.size(); ++i) {
      arena.execute([&] { integrator.integrate(map, scans[i].train, scans[i].origin); });
      progress.update(i + 1);
    }
    out.probability = [&map](const Point3f& x) -> std::optional<double> {
      const auto l = map.logOddsAt(x);
      if (!l) return std::nullopt;
      return 1.0 / (1.0 + std::exp(-static_cast<double>(*l)));
    };
    return {};
  }
  auto options = kernel::KernelOptions::defaults(*kernel::parseKernelMethod(method));
  options.max_range = o.max_range;
  options.seed = run_seed;
  if (options.method == kernel::KernelMethod::kAkimap) options.free_step = o.akimap_free_step;
  if (auto ok = kernel::applySettings(options, o.kernel_settings); !ok) {
    return makeError("--kernel-set: " + ok.error().message);
  }
  out.kernel_map = std::make_unique<kernel::KernelMap>(o.resolution, options);
  kernel::KernelMap& map = *out.kernel_map;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    arena.execute([&] { map.integrate(scans[i].train, scans[i].origin); });
    progress.update(i + 1, std::to_string(map.knownCells()) + " known cells");
  }
  out.probability = [&map](const Point3f& x) {
    const auto key = map.grid().pointToKey(x);
    return key ? map.probability(*key) : std::nullopt;
  };
  return {};
}

/// One method on one run's scans: build, score on the tests, and (first run) its curves and
/// slice picture.
Expected<RunResult> runMethod(const EvalOptions& o, const EvalData& data, const std::string& method,
                              int run, const std::vector<EvalScan>& scans,
                              const std::vector<TestPoint>& tests, tbb::task_arena& arena,
                              Curves& curves) {
  Progress progress("densemap-eval: run " + std::to_string(run + 1) + " " + method + " scan",
                    scans.size());
  RunResult r;
  const auto t0 = std::chrono::steady_clock::now();
  MethodMap map;
  if (auto ok = buildMap(o, method, o.seed + static_cast<std::uint64_t>(run), scans, arena,
                         progress, map);
      !ok) {
    return std::unexpected(ok.error());
  }
  r.build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.ms_per_scan = 1000.0 * r.build_s / static_cast<double>(scans.size());
  std::vector<eval::Prediction> predictions;
  predictions.reserve(tests.size());
  for (const TestPoint& t : tests) {
    const auto p = map.probability(t.x);
    predictions.push_back({p.value_or(0.5), t.occupied, p.has_value()});
  }
  r.metrics = eval::evaluate(predictions);
  if (run == 0 && !o.roc_prefix.empty()) {
    if (auto ok = addRocCurve(o, method, predictions, r.metrics.auc, curves); !ok) {
      return std::unexpected(ok.error());
    }
  }
  if (run == 0 && !o.reliability_prefix.empty()) {
    curves.reliability.push_back({method, r.metrics.ece, r.metrics.reliability});
  }
  if (run == 0 && !o.slice_prefix.empty()) {
    auto ok = writeSlice(o, data.frame, method,
                         [&](const Point3f& x) { return map.probability(x).value_or(0.5); });
    if (!ok) return std::unexpected(ok.error());
  }
  return r;
}

Expected<void> checkOptions(const EvalOptions& o, const std::vector<std::string>& methods) {
  if (!(o.resolution > 0.0 && o.resolution <= 10.0)) {
    return makeError("--resolution must be in (0, 10]");
  }
  if (methods.empty()) return makeError("--method lists no method");
  for (const std::string& m : methods) {
    if (m != "raycast" && !kernel::parseKernelMethod(m)) {
      return makeError("unknown method '" + m +
                       "' (expected akimap, bgk, bgkl, raycast or akimap_rays)");
    }
  }
  kernel::KernelOptions check;
  if (auto set = kernel::applySettings(check, o.kernel_settings); !set) {
    return makeError("--kernel-set: " + set.error().message);
  }
  return {};
}

Expected<void> evaluate(const EvalOptions& o) {
  const std::vector<std::string> methods = splitList(o.methods_list);
  if (auto ok = checkOptions(o, methods); !ok) return ok;
  auto data = loadEvalData(o);
  if (!data) return std::unexpected(data.error());
  tbb::task_arena arena(o.threads > 0 ? o.threads : tbb::task_arena::automatic);
  std::vector<TestPoint> oracle_tests;
  if (o.protocol == "oracle") {
    auto tests = oracleTests(o, data->frame);
    if (!tests) return std::unexpected(tests.error());
    oracle_tests = std::move(*tests);
  }
  std::vector<std::vector<RunResult>> results(methods.size());  // [method][run]
  Curves curves;
  for (int run = 0; run < o.runs; ++run) {
    const std::uint64_t run_seed = o.seed + static_cast<std::uint64_t>(run);
    std::vector<EvalScan> scans(data->clouds.size());
    std::vector<TestPoint> tests = oracle_tests;
    for (std::size_t i = 0; i < data->clouds.size(); ++i) {
      if (o.protocol == "oracle") {
        scans[i] = {data->clouds[i], data->origins[i]};
      } else {
        split(data->clouds[i], data->origins[i], run_seed, i, o.resolution, scans[i], tests);
      }
    }
    for (std::size_t m = 0; m < methods.size(); ++m) {
      auto r = runMethod(o, *data, methods[m], run, scans, tests, arena, curves);
      if (!r) return std::unexpected(r.error());
      results[m].push_back(std::move(*r));
    }
  }
  if (auto ok = writeCurves(o, curves); !ok) return ok;
  return reportResults(o, methods, results, data->clouds.size());
}

}  // namespace
}  // namespace densemap::tools

static int runMain(int argc, char** argv) {
  densemap::tools::EvalOptions options;
  CLI::App app{"densemap-eval: accuracy of dense and log-odds maps (hold-out protocol)"};
  densemap::tools::addEvalOptions(app, options);
  CLI11_PARSE(app, argc, argv);
  if (auto ok = densemap::tools::evaluate(options); !ok) {
    std::fprintf(stderr, "densemap-eval: error: %s\n", ok.error().message.c_str());
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-eval", [&] { return runMain(argc, argv); });
}
