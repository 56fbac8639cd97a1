#pragma once

#include <cstddef>

#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// Cell-by-cell comparison of two maps over the union of their known cells.
struct MapDiff {
  std::size_t union_cells = 0;
  std::size_t only_in_a = 0;
  std::size_t only_in_b = 0;
  std::size_t value_mismatch = 0;  // known in both, log-odds not bit-identical
  float max_abs_difference = 0.0F;

  [[nodiscard]] std::size_t differing() const { return only_in_a + only_in_b + value_mismatch; }
};

[[nodiscard]] MapDiff diffMaps(const OccupancyMap& a, const OccupancyMap& b);

}  // namespace densemap
