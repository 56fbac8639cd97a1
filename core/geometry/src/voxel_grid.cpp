#include "densemap/geometry/voxel_grid.hpp"

#include <cstdio>
#include <cstdlib>

namespace densemap {

VoxelGrid::VoxelGrid(double resolution_m)
    : resolution_m_(resolution_m), resolution_factor_(1.0 / resolution_m) {
  if (!(std::isfinite(resolution_m) && resolution_m > 0.0)) {
    std::fprintf(stderr, "densemap: VoxelGrid resolution must be finite and > 0, got %g\n",
                 resolution_m);
    std::abort();
  }
}

}  // namespace densemap
