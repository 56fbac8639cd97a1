#pragma once

// ROS 2 recordings (MCAP bags) as densemap datasets: read as scans (PointCloud2 + TF), written
// from any dataset as `densemap replay --ros` publishes it.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "densemap/io/scan_source.hpp"
#include "densemap/ros2/mcap.hpp"

namespace densemap::ros2 {

struct RecordingOptions {
  /// The frame scans are posed in; when a cloud's TF tree has no such frame, the tree's root.
  std::string world_frame = "map";
  std::string cloud_topic;  // empty: every sensor_msgs/msg/PointCloud2 topic
  std::size_t max_points = 2'000'000;
};

/// A ROS 2 bag (`.mcap`, rosbag2's `.db3`, or a rosbag2 directory with one of them) as
/// sensor-frame scans: every CDR sensor_msgs/msg/PointCloud2 message (by
/// log time), posed by the bag's /tf and /tf_static (tf2_msgs/msg/TFMessage) at the cloud's
/// stamp, interpolated as the server's TF buffer does. Clouds without a transform at their
/// stamp (before the first TF sample, say) are skipped and counted in describe(). A bag cut
/// short keeps its complete messages.
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openRecording(
    const std::filesystem::path& path, const RecordingOptions& options = {});

/// openRecording for `.mcap` and `.db3` files and rosbag2 directories (metadata.yaml),
/// openScanSource for everything else.
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openAnyScanSource(
    const std::filesystem::path& path);

/// Writes scans [first, first + count) of `source` (sensor frame) as a bag (`.db3`: rosbag2's
/// SQLite storage, `compression` unused; else MCAP), as
/// `densemap replay --ros` publishes them (ReplayFrames, 10 Hz): PointCloud2 of x, y, z on
/// /points in frame lidar, odom -> base_link on /tf per scan, map -> odom and base_link ->
/// lidar on /tf_static. `progress(n)` after the n-th scan.
[[nodiscard]] Expected<void> writeRecording(const ScanSource& source, std::size_t first,
                                            std::size_t count, const std::filesystem::path& file,
                                            McapCompression compression,
                                            const std::function<void(std::size_t)>& progress = {});

}  // namespace densemap::ros2
