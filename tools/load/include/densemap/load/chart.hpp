#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap::load {

/// A line of a chart panel; NaN values leave gaps.
struct Series {
  std::string label;
  std::array<std::uint8_t, 3> colour{0, 0, 0};
  std::vector<double> y;
};

/// Series that share a y axis from 0 to their largest value (printed at the axis top).
struct Panel {
  std::string title;
  std::vector<Series> series;
};

/// A PNG of stacked panels over the same x values (e.g. seconds), with titles, legends and axis
/// limits drawn in a small built-in font (no plotting library needed).
[[nodiscard]] Expected<void> writeChart(const std::filesystem::path& file, const std::string& title,
                                        const std::string& x_label, const std::vector<double>& x,
                                        const std::vector<Panel>& panels);

}  // namespace densemap::load
