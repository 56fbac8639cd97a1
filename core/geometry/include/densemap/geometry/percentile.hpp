#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

namespace densemap {

/// The one percentile of densemap (server status, load reports, benchmarks, the CLI's replay):
/// nearest rank, the smallest value with at least q of the samples at or below it, so a p99 of
/// 100 samples is the 99th smallest. `sorted` ascending; 0 when empty.
[[nodiscard]] inline double nearestRank(std::span<const double> sorted, double q) {
  if (sorted.empty()) return 0.0;
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size())));
  return sorted[std::clamp<std::size_t>(rank, 1, sorted.size()) - 1];
}

/// nearestRank of unsorted values (sorts its copy).
[[nodiscard]] inline double percentile(std::vector<double> values, double q) {
  std::sort(values.begin(), values.end());
  return nearestRank(values, q);
}

}  // namespace densemap
