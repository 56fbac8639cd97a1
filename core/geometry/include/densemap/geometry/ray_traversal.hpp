#pragma once

#include <cmath>
#include <limits>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"

namespace densemap {

/// Visits the voxels that OctoMap 1.9.7's `OcTreeBaseImpl::computeRayKeys(origin, end)` returns,
/// in the same order: the origin's voxel first, the end point's voxel excluded. The arithmetic
/// is copied operation for operation (float direction and length, double tMax/tDelta, the
/// `(float)` half-step, strict comparisons, the `dist > length` stop) because a different but
/// "more correct" rounding would visit different voxels on boundary cases.
/// (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing", 1987.)
///
/// Returns false (visiting nothing) when origin or end lies outside the addressable range.
/// `visit(const VoxelKey&)` is called once per voxel. Thread-safe (pure).
template <class Visitor>
bool traverseRay(const VoxelGrid& grid, const Point3f& origin, const Point3f& end,
                 Visitor&& visit) {
  const auto key_origin = grid.pointToKey(origin);
  const auto key_end = grid.pointToKey(end);
  if (!key_origin || !key_end) return false;
  if (*key_origin == *key_end) return true;
  visit(*key_origin);

  // Vector3 arithmetic of OctoMap, one float operation at a time.
  float dir[3] = {end.x() - origin.x(), end.y() - origin.y(), end.z() - origin.z()};
  const float norm_sq = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
  const float length = static_cast<float>(std::sqrt(static_cast<double>(norm_sq)));
  for (float& d : dir) d /= length;

  const double resolution = grid.resolution();
  int step[3];
  double t_max[3];
  double t_delta[3];
  VoxelKey current = *key_origin;
  for (int i = 0; i < 3; ++i) {
    step[i] = dir[i] > 0.0F ? 1 : (dir[i] < 0.0F ? -1 : 0);
    if (step[i] != 0) {
      double voxel_border = grid.keyToCoord(current[i]);
      voxel_border += static_cast<float>(step[i] * resolution * 0.5);
      t_max[i] = (voxel_border - static_cast<double>(origin[i])) / static_cast<double>(dir[i]);
      t_delta[i] = resolution / static_cast<double>(std::fabs(dir[i]));
    } else {
      t_max[i] = std::numeric_limits<double>::max();
      t_delta[i] = std::numeric_limits<double>::max();
    }
  }

  while (true) {
    int dim;
    if (t_max[0] < t_max[1]) {
      dim = t_max[0] < t_max[2] ? 0 : 2;
    } else {
      dim = t_max[1] < t_max[2] ? 1 : 2;
    }
    current[dim] = static_cast<std::uint16_t>(current[dim] + step[dim]);
    t_max[dim] += t_delta[dim];
    if (current == *key_end) break;
    const double dist_from_origin = std::min(std::min(t_max[0], t_max[1]), t_max[2]);
    // Accumulated rounding can step past the end voxel without entering it; OctoMap stops
    // once the travelled distance exceeds the ray length.
    if (dist_from_origin > static_cast<double>(length)) break;
    visit(current);
  }
  return true;
}

/// Convenience form returning the keys (tests, tools); hot paths use the visitor form.
[[nodiscard]] inline bool computeRayKeys(const VoxelGrid& grid, const Point3f& origin,
                                         const Point3f& end, std::vector<VoxelKey>& keys) {
  keys.clear();
  return traverseRay(grid, origin, end, [&keys](const VoxelKey& k) { keys.push_back(k); });
}

}  // namespace densemap
