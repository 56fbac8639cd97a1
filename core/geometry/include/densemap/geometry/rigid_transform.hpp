#pragma once

#include <Eigen/Geometry>

#include "densemap/geometry/error.hpp"
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

/// The largest sensor position a file may give (m): the map's keys cover +-32768 voxels, and
/// nothing a robot maps lies farther (a 1e30 translation would write an empty map).
inline constexpr double kMaxPoseTranslationM = 1e6;

/// The one rule for a pose read from outside (files; scans have their own quaternion and
/// position limits): finite, translation within kMaxPoseTranslationM, rotation orthonormal
/// (|R^T R - I| <= 1e-3 per entry) and proper (det R > 0: no reflection). The error says which.
[[nodiscard]] Expected<void> checkRigidPose(const Transform& T);

}  // namespace densemap
