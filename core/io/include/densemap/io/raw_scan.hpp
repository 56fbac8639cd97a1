#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace densemap {

/// A scan as it arrives from outside (DDS, files), before any check: flat coordinates in the
/// sensor frame and a pose as translation + quaternion (w, x, y, z).
struct RawScan {
  std::string sensor_id;
  std::uint64_t seq = 0;
  std::int64_t stamp_ns = 0;
  std::array<double, 3> t_world_sensor{};
  std::array<double, 4> q_world_sensor{1, 0, 0, 0};
  std::vector<float> xyz;        // 3 per point
  std::vector<float> intensity;  // empty or one per point
  std::chrono::steady_clock::time_point received = std::chrono::steady_clock::now();
};

/// One corrected pose: the scan of the correction's sensor stamped `stamp_ns` now has this
/// pose (world <- sensor: translation, quaternion w, x, y, z), as a scan carries it.
struct CorrectedPose {
  std::int64_t stamp_ns = 0;
  std::array<double, 3> t{};
  std::array<double, 4> q{1, 0, 0, 0};
};

/// New poses for past scans of one sensor (densemap/pose_correction, or a ROS 2 robot's
/// corrected path).
struct PoseCorrection {
  std::string sensor_id;
  std::vector<CorrectedPose> poses;
};

/// The most poses one correction may carry.
inline constexpr std::size_t kMaxCorrectedPoses = 100'000;

/// A pose in the raw form scans and pose corrections carry: translation and unit quaternion
/// (w, x, y, z). Conversions: densemap/io/scan.hpp.
struct ScanPose {
  std::array<double, 3> t{};
  std::array<double, 4> q{1, 0, 0, 0};
};

/// The memory a waiting scan holds: its arrays and strings (the ingest queue's byte budget).
[[nodiscard]] inline std::size_t rawScanBytes(const RawScan& scan) {
  return sizeof(RawScan) + scan.sensor_id.capacity() +
         (scan.xyz.capacity() + scan.intensity.capacity()) * sizeof(float);
}

struct Scan;

/// The raw form of a scan as a sender publishes it: sensor-frame points (world-frame scans are
/// re-expressed in the sensor frame) and the pose as translation + unit quaternion.
[[nodiscard]] RawScan toRawScan(const Scan& scan, std::uint64_t seq, const std::string& sensor_id);

}  // namespace densemap
