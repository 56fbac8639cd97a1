#pragma once

#include <filesystem>
#include <string>
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
[[nodiscard]] Expected<void> writeRocSvg(const std::filesystem::path& path, const std::string& title,
                                         const std::vector<RocSeries>& series);

}  // namespace densemap::tools
