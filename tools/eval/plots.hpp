#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "densemap/eval/metrics.hpp"
#include "densemap/geometry/error.hpp"

namespace densemap::tools {

/// One method's ROC curve for the plot.
struct RocSeries {
  std::string name;
  double auc = 0.0;
  std::vector<eval::RocPoint> points;
};

/// An SVG line plot of ROC curves (false positive rate against true positive rate), one colour
/// per series, with the chance diagonal and a legend carrying each AUC.
[[nodiscard]] Expected<void> writeRocSvg(const std::filesystem::path& path,
                                         const std::string& title,
                                         const std::vector<RocSeries>& series);

/// One method's reliability diagram for the plot.
struct ReliabilitySeries {
  std::string name;
  double ece = 0.0;
  std::vector<eval::ReliabilityBin> bins;
};

/// An SVG reliability diagram: per method, the observed share of occupied test points against
/// the mean predicted probability of each non-empty bin, with the diagonal of perfect
/// calibration and a legend carrying each expected calibration error.
[[nodiscard]] Expected<void> writeReliabilitySvg(const std::filesystem::path& path,
                                                 const std::string& title,
                                                 const std::vector<ReliabilitySeries>& series);

}  // namespace densemap::tools
