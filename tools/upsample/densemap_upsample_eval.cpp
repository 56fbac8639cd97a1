// densemap-upsample-eval: LiDAR range-image upsampling measured as in the dissertation's
// Table 4.1. densemap-sim's scenes are scanned from the same poses by a sparse input sensor
// (16 x 1024 by default) and by denser target sensors; each method upsamples the input to each
// target grid; MAE of range and voxel IoU / precision / recall / F1 of the points compare it
// with what the target sensor saw. With --real, real scans lose every n-th beam and are
// upsampled back. Rooms: upsample_eval_options (the command line), upsample_eval_score (a
// method's score on one scan, sums), upsample_eval_sim and upsample_eval_real (the two
// test sets); here: the methods, the run and the table.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <cstdio>
#include <string>
#include <vector>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/lists.hpp"
#include "densemap/io/file_bytes.hpp"
#include "upsample_eval.hpp"

namespace densemap::tools {
namespace {

Expected<Methods> loadMethods(const UpsampleEvalOptions& o) {
  Methods methods;
  for (const std::string& m : splitList(o.methods_list)) {
    auto parsed = upsample::parseInterpolation(m);
    if (!parsed) return std::unexpected(parsed.error());
    if (*parsed == upsample::Interpolation::kIln && !methods.model) {
      auto loaded = upsample::IlnModel::load(o.model_path);
      if (!loaded) return makeError(loaded.error().message + " (--model)");
      methods.model = std::make_shared<const upsample::IlnModel>(std::move(*loaded));
      std::fprintf(stderr,
                   "densemap-upsample-eval: ILN model %s: width %d, %d blocks, dim %d, "
                   "%zu parameters\n",
                   o.model_path.c_str(), methods.model->width(), methods.model->blocks(),
                   methods.model->dim(), methods.model->parameters());
    }
    methods.list.push_back(*parsed);
  }
  if (methods.list.empty()) return makeError("--methods lists no method");
  return methods;
}

/// The table (and --json): every (method, target) of the simulated scenes, then every (split,
/// reduction, method) of the real scans.
Expected<void> report(const UpsampleEvalOptions& o, const Methods& methods,
                      const RangeLayout& input, const std::vector<RangeLayout>& targets,
                      SimSums& sums, RealResults& real) {
  std::printf(
      "densemap-upsample-eval: scenes %s, seeds %s, %d scans each, input %dx%d, FOV "
      "[%g, %g] deg, max range %g m, voxel %g m\n",
      o.scenes_list.c_str(), o.seeds_list.c_str(), o.scans, input.rows, input.cols, o.bottom, o.top,
      o.max_range, o.voxel);
  std::printf("%-9s %-10s %8s %8s %7s %9s %7s %7s %9s %7s\n", "method", "target", "mae_m",
              "coverage", "iou", "precision", "recall", "f1", "ms/scan", "ms_p50");
  std::string json = "{\"results\": [";
  bool first = true;
  const auto row = [&](upsample::Interpolation method, const std::string& dataset,
                       const RangeLayout& grid, Sum& sum, const std::string& suffix) {
    const std::string name(upsample::interpolationName(method));
    const double n = sum.scans;
    const std::string size = std::to_string(grid.rows) + "x" + std::to_string(grid.cols);
    const double p50 = sum.msP50();
    std::printf("%-9s %-10s %8.3f %8.3f %7.3f %9.3f %7.3f %7.3f %9.1f %7.1f%s\n", name.c_str(),
                size.c_str(), sum.mae / n, sum.coverage / n, sum.iou / n, sum.precision / n,
                sum.recall / n, sum.f1 / n, sum.ms / n, p50, suffix.c_str());
    char entry[512];
    std::snprintf(entry, sizeof(entry),
                  "%s{\"method\": \"%s\", \"dataset\": \"%s\", \"rows\": %d, \"cols\": %d, "
                  "\"mae\": %.5f, \"iou\": %.5f, \"precision\": %.5f, \"recall\": %.5f, "
                  "\"f1\": %.5f, \"ms_per_scan\": %.3f, \"ms_p50\": %.3f}",
                  first ? "" : ", ", name.c_str(), dataset.c_str(), grid.rows, grid.cols,
                  sum.mae / n, sum.iou / n, sum.precision / n, sum.recall / n, sum.f1 / n,
                  sum.ms / n, p50);
    json += entry;
    first = false;
  };
  for (std::size_t t = 0; t < targets.size(); ++t) {
    for (std::size_t m = 0; m < methods.list.size(); ++m) {
      row(methods.list[m], "sim:" + o.scenes_list, targets[t], sums[{m, t}], "");
    }
  }
  for (auto& [key, sum] : real.sums) {
    const auto [split, reduce, m] = key;
    const Split& s = real.splits[split];
    const std::string every = std::to_string(real.reduces[reduce]);
    row(methods.list[m], "real:" + o.real_path + ":" + s.name + ":every" + every, real.layout, sum,
        "  (real " + s.name + " " + std::to_string(s.first) + "-" + std::to_string(s.last) +
            ", every " + every + "-th beam)");
  }
  json += "]}\n";
  if (!o.json_path.empty()) return writeFileAtomically(o.json_path, json);
  return {};
}

Expected<void> evaluate(const UpsampleEvalOptions& o) {
  auto methods = loadMethods(o);
  if (!methods) return std::unexpected(methods.error());
  if (!(o.voxel > 0.0 && o.voxel <= 10.0)) return makeError("--voxel must be in (0, 10]");
  if (!(o.max_range > 1.0 && o.max_range <= 1000.0)) {
    return makeError("--max-range must be in (1, 1000]");
  }
  auto input = upsample::parseRangeLayout(o.input_text, o.top, o.bottom);
  if (!input) return std::unexpected(input.error());
  std::vector<RangeLayout> targets;
  for (const std::string& t : splitList(o.targets_list)) {
    auto layout = upsample::parseRangeLayout(t, o.top, o.bottom);
    if (!layout) return std::unexpected(layout.error());
    targets.push_back(*layout);
  }
  tbb::task_arena arena(o.threads > 0 ? o.threads : tbb::task_arena::automatic);
  auto sums = scoreSimulated(o, *methods, *input, targets, arena);
  if (!sums) return std::unexpected(sums.error());
  RealResults real;
  if (!o.real_path.empty()) {
    auto scored = scoreReal(o, *methods, arena);
    if (!scored) return std::unexpected(scored.error());
    real = std::move(*scored);
  }
  return report(o, *methods, *input, targets, *sums, real);
}

}  // namespace
}  // namespace densemap::tools

static int runMain(int argc, char** argv) {
  densemap::tools::UpsampleEvalOptions options;
  CLI::App app{"densemap-upsample-eval: LiDAR upsampling accuracy on simulated scenes"};
  densemap::tools::addUpsampleEvalOptions(app, options);
  CLI11_PARSE(app, argc, argv);
  if (auto ok = densemap::tools::evaluate(options); !ok) {
    std::fprintf(stderr, "densemap-upsample-eval: error: %s\n", ok.error().message.c_str());
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-upsample-eval", [&] { return runMain(argc, argv); });
}
