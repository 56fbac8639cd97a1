#include "densemap/map/map_diff.hpp"

#include <cmath>
#include <unordered_map>

namespace densemap {

MapDiff diffMaps(const OccupancyMap& a, const OccupancyMap& b) {
  std::unordered_map<std::uint64_t, float> cells_a;
  cells_a.reserve(a.knownCells());
  a.forEachKnown([&](const VoxelKey& k, float v) { cells_a.emplace(k.packed(), v); });

  MapDiff diff;
  std::size_t matched = 0;
  b.forEachKnown([&](const VoxelKey& k, float v) {
    const auto it = cells_a.find(k.packed());
    if (it == cells_a.end()) {
      ++diff.only_in_b;
      return;
    }
    ++matched;
    if (it->second != v) {
      ++diff.value_mismatch;
      diff.max_abs_difference = std::max(diff.max_abs_difference, std::fabs(it->second - v));
    }
  });
  diff.only_in_a = cells_a.size() - matched;
  diff.union_cells = cells_a.size() + diff.only_in_b;
  return diff;
}

}  // namespace densemap
