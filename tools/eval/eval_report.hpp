#pragma once

#include <string>
#include <vector>

#include "densemap/eval/metrics.hpp"
#include "densemap/geometry/error.hpp"
#include "eval_options.hpp"
#include "plots.hpp"

namespace densemap::tools {

/// One method's run: its scores and how long its map took.
struct RunResult {
  eval::Metrics metrics;
  double build_s = 0.0;
  double ms_per_scan = 0.0;
};

/// The first run's curves, collected method by method (--roc, --reliability).
struct Curves {
  std::vector<RocSeries> roc;
  std::vector<ReliabilitySeries> reliability;
};

/// Writes PREFIX_<method>.csv of a method's ROC curve and keeps it for the plot.
[[nodiscard]] Expected<void> addRocCurve(const EvalOptions& o, const std::string& method,
                                         const std::vector<eval::Prediction>& predictions,
                                         double auc, Curves& curves);
/// Writes the plots (PREFIX.svg) and the reliability table (PREFIX.csv) of the curves kept.
[[nodiscard]] Expected<void> writeCurves(const EvalOptions& o, const Curves& curves);
/// Prints the table of every method's mean over the runs (AUC with its spread) and writes
/// --json when asked.
[[nodiscard]] Expected<void> reportResults(const EvalOptions& o,
                                           const std::vector<std::string>& methods,
                                           const std::vector<std::vector<RunResult>>& results,
                                           std::size_t scans);

}  // namespace densemap::tools
