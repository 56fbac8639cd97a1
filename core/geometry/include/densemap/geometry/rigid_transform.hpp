#pragma once

#include <Eigen/Geometry>

#include "densemap/geometry/point_cloud.hpp"

namespace densemap {

/// A rigid transform kept in double precision; `T_world_sensor * p_sensor = p_world`.
using Transform = Eigen::Isometry3d;

/// Transforms points in double precision and rounds to float once: the world-frame cloud that
/// every integration method (and the OctoMap oracle) receives.
[[nodiscard]] PointCloud transformPoints(const Transform& T_world_sensor,
                                         const PointCloud& points_sensor);

/// Sensor origin in the world frame, rounded to float like the points.
[[nodiscard]] Point3f sensorOrigin(const Transform& T_world_sensor);

/// Builds a transform from the first three rows of a row-major 4x4 matrix (KITTI layout).
[[nodiscard]] Transform transformFromRows(const double (&rows)[12]);

/// Builds a transform from translation and unit quaternion (w, x, y, z).
[[nodiscard]] Transform transformFromTranslationQuaternion(const Eigen::Vector3d& t, double qw,
                                                           double qx, double qy, double qz);

}  // namespace densemap
