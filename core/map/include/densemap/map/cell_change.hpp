#pragma once

// One cell's change, as deltas, tiles and commands report it: plain data (no map internals).
#include <vector>

#include "densemap/geometry/voxel_key.hpp"

namespace densemap {

/// A cell's value after a change; `known == false` means the cell was erased.
struct CellChange {
  VoxelKey key;
  float log_odds = 0.0F;
  bool known = true;
};
using CellChanges = std::vector<CellChange>;

}  // namespace densemap
