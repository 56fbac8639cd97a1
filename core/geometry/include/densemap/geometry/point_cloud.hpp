#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <vector>

namespace densemap {

/// Points as float triples, the precision OctoMap's `point3d` uses; the frame is named by the
/// variable (`points_sensor`, `points_world`).
using Point3f = Eigen::Vector3f;
using PointCloud = std::vector<Point3f>;

/// Removes NaN/Inf points (OctoMap's key conversion is undefined for them); returns how many.
inline std::size_t removeNonFinite(PointCloud& points) {
  const auto end = std::remove_if(points.begin(), points.end(),
                                  [](const Point3f& p) { return !p.allFinite(); });
  const auto removed = static_cast<std::size_t>(points.end() - end);
  points.erase(end, points.end());
  return removed;
}

}  // namespace densemap
