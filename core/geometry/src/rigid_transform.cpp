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

Expected<void> checkRigidPose(const Transform& T) {
  const Eigen::Matrix4d& m = T.matrix();
  if (!m.allFinite()) return makeError("the pose has a NaN or infinite entry");
  if (T.translation().cwiseAbs().maxCoeff() > kMaxPoseTranslationM) {
    return makeError("the pose's translation is beyond +-1e6 m");
  }
  const Eigen::Matrix3d r = T.linear();
  const double off = (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off > 1e-3) {
    return makeError(
        "the pose's rotation is not orthonormal (scaled, sheared or zero: "
        "|R^T R - I| = " +
        std::to_string(off) + ")");
  }
  if (r.determinant() < 0) return makeError("the pose's rotation is a reflection (det R < 0)");
  return {};
}

}  // namespace densemap
