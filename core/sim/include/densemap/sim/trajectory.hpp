#pragma once

#include <vector>

#include "densemap/geometry/rigid_transform.hpp"

namespace densemap {

/// `n` sensor poses spaced evenly along the polyline through `waypoints`, each facing along
/// the path (yaw only). One waypoint gives n poses turning in place.
[[nodiscard]] std::vector<Transform> trajectoryAlong(const std::vector<Eigen::Vector3d>& waypoints,
                                                     int n);

/// `n` sensor poses standing at `stations` in turn (n / stations each, the first stations
/// taking one more when it does not divide), each turned about z by a different yaw, so
/// repeated scans from one place sample other directions.
[[nodiscard]] std::vector<Transform> posesAtStations(const std::vector<Eigen::Vector3d>& stations,
                                                     int n);

}  // namespace densemap
