#pragma once

#include <cstdint>
#include <string>

#include "densemap/ros2/tf_buffer.hpp"

namespace densemap::ros2 {

/// How `densemap replay --ros` presents a dataset as a robot's ROS 2 stack would:
///   map -> odom             static, identity
///   odom -> base_link       moving: one sample per scan, at stampOf(k)
///   base_link -> <sensor>   static: the LiDAR's mount (kMount below)
/// and each scan as a PointCloud2 in <sensor>, stamped stampOf(k) + stamp_offset * period (0:
/// at its pose's sample; 0.5: halfway to the next one, so the server must interpolate and wait
/// for the next sample). The dataset's world frame is `map`.
struct ReplayFrames {
  std::string map = "map", odom = "odom", base = "base_link", sensor = "lidar";
  std::int64_t stamp_base_ns = 0;
  std::int64_t period_ns = 100'000'000;
  double stamp_offset = 0.0;

  [[nodiscard]] std::int64_t stampOf(std::size_t k) const {
    return stamp_base_ns + static_cast<std::int64_t>(k) * period_ns;
  }
  [[nodiscard]] std::int64_t cloudStamp(std::size_t k) const {
    return stampOf(k) + static_cast<std::int64_t>(stamp_offset * static_cast<double>(period_ns));
  }
};

/// base_link -> sensor: 0.2 m forward, 0.45 m up, pitched down 2 degrees.
[[nodiscard]] TfSample sensorMount();
/// odom -> base_link at stampOf(k) for a scan taken at T_world_sensor.
[[nodiscard]] TfSample odomToBase(const Eigen::Isometry3d& T_world_sensor, std::int64_t stamp_ns);

}  // namespace densemap::ros2
