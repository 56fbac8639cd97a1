#include "densemap/ros2/replay_frames.hpp"

namespace densemap::ros2 {

TfSample sensorMount() {
  return {0,
          {0.2, 0.0, 0.45},
          Eigen::Quaterniond(Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()))};
}

TfSample odomToBase(const Eigen::Isometry3d& T_world_sensor, std::int64_t stamp_ns) {
  const TfSample m = sensorMount();
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  mount.linear() = m.q.toRotationMatrix();
  mount.translation() = m.t;
  const Eigen::Isometry3d T = T_world_sensor * mount.inverse();
  return {stamp_ns, T.translation(), Eigen::Quaterniond(T.linear()).normalized()};
}

}  // namespace densemap::ros2
