#pragma once
// Odometry drift for the pose-correction tests (header-only: for targets that link densemap::io).
#include <Eigen/Geometry>

#include "densemap/io/raw_scan.hpp"

namespace densemap::test {

/// `scan` as odometry that drifted by `k` steps would place it: turned `yaw_step` rad a step
/// about the world's z axis and moved 1 cm along x and 0.5 cm along y a step.
inline RawScan drifted(RawScan scan, int k, double yaw_step) {
  const Eigen::Quaterniond drift(Eigen::AngleAxisd(yaw_step * k, Eigen::Vector3d::UnitZ()));
  const Eigen::Quaterniond q(scan.q_world_sensor[0], scan.q_world_sensor[1],
                             scan.q_world_sensor[2], scan.q_world_sensor[3]);
  const Eigen::Vector3d t(scan.t_world_sensor[0], scan.t_world_sensor[1], scan.t_world_sensor[2]);
  const Eigen::Quaterniond q2 = (drift * q).normalized();
  const Eigen::Vector3d t2 = drift * t + Eigen::Vector3d(0.01 * k, 0.005 * k, 0);
  scan.q_world_sensor = {q2.w(), q2.x(), q2.y(), q2.z()};
  scan.t_world_sensor = {t2.x(), t2.y(), t2.z()};
  return scan;
}

}  // namespace densemap::test
