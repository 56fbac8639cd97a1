#pragma once

#include <vector>

#include "densemap/geometry/rigid_transform.hpp"

namespace densemap {

/// `n` sensor poses spaced evenly along the polyline through `waypoints`, each facing along
/// the path (yaw only). One waypoint gives n poses turning in place.
[[nodiscard]] std::vector<Transform> trajectoryAlong(const std::vector<Eigen::Vector3d>& waypoints,
                                                     int n);

}  // namespace densemap
