#pragma once

#include <chrono>
#include <memory>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/ros2/replay_frames.hpp"
#include "densemap/wire/dds.hpp"

namespace densemap::cli {

/// `densemap replay --ros`: publishes scans as a ROS 2 robot would (ros2/replay_frames.hpp):
/// sensor_msgs/PointCloud2 on `topic` and tf2_msgs/TFMessage on rt/tf and rt/tf_static, all
/// under the robot's namespace `ns` when one is given (rt/robot1/points, rt/robot1/tf...).
/// Loopback only, like every densemap participant (docs/architecture.md).
class RosReplayPublisher {
 public:
  /// `static_delay` > 0: /tf_static goes out that long after creation (with the first scan
  /// after it), as a late static broadcaster's does; else at once.
  [[nodiscard]] static Expected<std::unique_ptr<RosReplayPublisher>> create(
      const dds::ParticipantOptions& participant, const std::string& ns, const std::string& topic,
      const ros2::ReplayFrames& frames, bool reliable,
      std::chrono::milliseconds static_delay = std::chrono::milliseconds(0));
  ~RosReplayPublisher();
  /// Waits (up to `timeout_ms`) until a reader matches the cloud topic.
  [[nodiscard]] Expected<void> waitForReader(int timeout_ms);
  /// The transforms of scan k (odom -> base_link at stampOf(k)), then its cloud.
  [[nodiscard]] Expected<void> publish(const RawScan& scan, std::size_t k);
  /// The odom -> base_link sample after the last scan, so a cloud stamped after its pose's
  /// sample can be interpolated.
  [[nodiscard]] Expected<void> finish(const RawScan& last, std::size_t k_after);

 private:
  struct Dds;
  RosReplayPublisher(const ros2::ReplayFrames& frames);
  [[nodiscard]] Expected<void> publishStatic();
  [[nodiscard]] Expected<void> publishStaticWhenDue(bool now);
  [[nodiscard]] Expected<void> publishTf(const ros2::TfSample& s, const std::string& parent,
                                         const std::string& child, bool is_static);
  ros2::ReplayFrames frames_;
  std::unique_ptr<Dds> dds_;
  bool static_sent_ = false;
  std::chrono::steady_clock::time_point static_due_{};
};

}  // namespace densemap::cli
