#pragma once

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

#include "densemap/client/client.hpp"
#include "ros_replay.hpp"

namespace densemap::cli {

/// `densemap replay`: a dataset's scans to the server at a rate (natively or as a ROS 2 robot),
/// optionally densified, with query load alongside; prints the server's counts and latencies.
class ReplayCommand {
 public:
  /// Adds the subcommand and its options to `app`.
  explicit ReplayCommand(CLI::App& app);
  [[nodiscard]] bool parsed() const { return command_->parsed(); }
  int run(const ClientOptions& options);

 private:
  CLI::App* command_;
  std::string data_;
  double rate_ = 10.0;
  bool recorded_rate_ = false;  // pace by the scans' own stamps (recordings)
  std::size_t first_ = 0, limit_ = 0, query_points_ = 0;
  std::string csv_;
  double bbox_edge_m_ = 0;
  std::string upsample_method_, upsample_input_ = "16x1024", upsample_output_ = "64x1024";
  std::string upsample_model_ = "models/iln.pb";
  double fov_top_ = 15.0, fov_bottom_ = -15.0;
  bool ros_ = false;
  std::string ros_topic_ = "/points";
  std::string ros_namespace_;  // a robot's namespace: its clouds and TF under it
  std::string sensor_id_ = "replay";
  ros2::ReplayFrames ros_frames_;
  bool ros_reliable_ = true;
  double ros_static_delay_s_ = 0;
};

}  // namespace densemap::cli
