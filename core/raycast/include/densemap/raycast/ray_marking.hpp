#pragma once

#include <cmath>
#include <cstddef>

#include "densemap/geometry/ray_traversal.hpp"
#include "densemap/map/scan_update.hpp"

namespace densemap {

/// Marks one measurement into a scan's update set exactly as OctoMap 1.9.7's
/// `OccupancyOcTreeBase::computeUpdate` does (no bounding box): cells crossed on the way are
/// free candidates, the end cell an occupied candidate; a ray longer than `max_range_m` (< 0:
/// unlimited) is cut there with float arithmetic and its end is not occupied.
/// Returns the number of cells visited (marked). Thread-safe for distinct `update`s.
inline std::size_t markRay(const VoxelGrid& grid, const Point3f& origin, const Point3f& end,
                           double max_range_m, ScanUpdate& update) {
  std::size_t visits = 0;
  auto mark_free = [&](const VoxelKey& k) {
    update.markFree(k);
    ++visits;
  };
  const float dx = end.x() - origin.x();
  const float dy = end.y() - origin.y();
  const float dz = end.z() - origin.z();
  const double norm = std::sqrt(static_cast<double>(dx * dx + dy * dy + dz * dz));
  if (max_range_m < 0.0 || norm <= max_range_m) {
    traverseRay(grid, origin, end, mark_free);
    if (const auto key = grid.pointToKey(end)) {
      update.markOccupied(*key);
      ++visits;
    }
    return visits;
  }
  // Vector3::normalized(): divide by the float-rounded double norm, then scale by (float)range.
  Point3f direction(dx, dy, dz);
  if (norm > 0.0) {
    const float len = static_cast<float>(norm);
    direction = Point3f(dx / len, dy / len, dz / len);
  }
  const float range = static_cast<float>(max_range_m);
  const Point3f cut_end(origin.x() + direction.x() * range, origin.y() + direction.y() * range,
                        origin.z() + direction.z() * range);
  traverseRay(grid, origin, cut_end, mark_free);
  return visits;
}

}  // namespace densemap
