#include "densemap/geometry/rigid_transform.hpp"

namespace densemap {

PointCloud transformPoints(const Transform& T_world_sensor, const PointCloud& points_sensor) {
  PointCloud points_world;
  points_world.reserve(points_sensor.size());
  for (const auto& p : points_sensor) {
    points_world.push_back((T_world_sensor * p.cast<double>()).cast<float>());
  }
  return points_world;
}

Point3f sensorOrigin(const Transform& T_world_sensor) {
  return T_world_sensor.translation().cast<float>();
}

Transform transformFromRows(const double (&rows)[12]) {
  Transform T = Transform::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) T.matrix()(r, c) = rows[r * 4 + c];
  }
  return T;
}

Transform transformFromTranslationQuaternion(const Eigen::Vector3d& t, double qw, double qx,
                                             double qy, double qz) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

}  // namespace densemap
