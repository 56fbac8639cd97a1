#pragma once

// The plain reference for the free capsules' tests: every voxel of a segment's box.

#include <algorithm>

#include <Eigen/Core>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/geometry/voxel_key.hpp"

namespace densemap::kernel::test {

/// f(key, d) for every voxel of the box of segment [a, b] widened by `margin` (clamped into the
/// addressable range: the voxels beyond it do not exist), d its centre's distance from the
/// segment.
template <class F>
void forEachVoxelOfSegmentBox(const VoxelGrid& grid, const Eigen::Vector3d& a,
                              const Eigen::Vector3d& b, double margin, F&& f) {
  const double edge = grid.halfExtent() - 1e-3;  // still inside as a float
  const Eigen::Vector3d lo = (a.cwiseMin(b).array() - margin).cwiseMax(-edge).cwiseMin(edge);
  const Eigen::Vector3d hi = (a.cwiseMax(b).array() + margin).cwiseMax(-edge).cwiseMin(edge);
  const VoxelKey klo = *grid.pointToKey(lo.cast<float>());
  const VoxelKey khi = *grid.pointToKey(hi.cast<float>());
  const Eigen::Vector3d seg = b - a;
  for (int z = klo.z; z <= khi.z; ++z) {
    for (int y = klo.y; y <= khi.y; ++y) {
      for (int x = klo.x; x <= khi.x; ++x) {
        const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                         static_cast<std::uint16_t>(z)};
        const Eigen::Vector3d c(grid.keyToCoord(k.x), grid.keyToCoord(k.y), grid.keyToCoord(k.z));
        const double t = std::clamp((c - a).dot(seg) / seg.squaredNorm(), 0.0, 1.0);
        f(k, (c - (a + t * seg)).norm());
      }
    }
  }
}

}  // namespace densemap::kernel::test
