#pragma once

#include <Eigen/Core>
#include <vector>

namespace densemap {

/// Points as float triples, the precision OctoMap's `point3d` uses; the frame is named by the
/// variable (`points_sensor`, `points_world`).
using Point3f = Eigen::Vector3f;
using PointCloud = std::vector<Point3f>;

}  // namespace densemap
