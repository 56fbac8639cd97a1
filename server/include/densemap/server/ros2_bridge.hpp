#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/status.hpp"

namespace densemap::server {

/// rmw_dds_common's Gid: 24 bytes on Humble, 16 from Iron on (one DDS type name for both, so
/// the server must be told which its robot runs: ros2.distro).
enum class RosGidLayout { kHumble, kIronAndLater };

/// At most this many robots (ros2.robots) and cloud topics in all, as many as the ingest keeps
/// sensors apart (SensorTally::kMaxSensors).
inline constexpr std::size_t kMaxRosRobots = SensorTally::kMaxSensors;

struct Ros2Options {
  std::vector<std::string> clouds{"/points"};  // ROS topic names
  /// Robots' namespaces: each reads `clouds` under its namespace and its own TF tree
  /// (<ns>/tf, <ns>/tf_static). Empty: one robot, `clouds` as given, TF on /tf, /tf_static.
  std::vector<std::string> robots;
  /// A glob on namespaces: a publisher of a `clouds` topic under a matching namespace adds
  /// that robot while the server runs (up to kMaxRosRobots). Empty: off.
  std::string robot_pattern;
  bool reliable_clouds = false;
  std::string world_frame = "map";
  /// A cloud whose transform is not there yet waits this long (octomap_server's TF filter
  /// keeps clouds 5 s: a late /tf_static, e.g. Fast DDS's answered at its next heartbeat 3 s
  /// later, loses none) ...
  std::chrono::milliseconds tf_wait{5000};
  /// ... at most this many clouds and bytes of points at once (the oldest gives way; one
  /// cloud always waits).
  std::size_t max_waiting = 20;
  std::size_t max_waiting_bytes = std::size_t{128} << 20;
  std::int64_t tf_buffer_ns = 10'000'000'000;
  double publish_period_s = 1.0;  // 0: no map topics
  std::string octomap_topic = "/octomap_binary", grid_topic = "/projected_map",
              centers_topic = "/octomap_point_cloud_centers";
  double grid_min_z_m = -1000.0, grid_max_z_m = 1000.0;
  /// With a distance field (esdf): its layer at this height as PointCloud2 (x y z distance)
  /// and as a costmap inflated by the robot's radius (nav_msgs/OccupancyGrid); "": off.
  std::string esdf_slice_topic = "/esdf_slice", costmap_topic = "/costmap";
  double esdf_slice_z_m = 0.0, robot_radius_m = 0.3;
  /// A robot's corrected trajectory (nav_msgs/Path, under its namespace like `clouds`): poses
  /// of `base_frame` in world_frame at its clouds' stamps, handed to the ingest as pose
  /// corrections of each of its cloud topics. "": not read.
  std::string corrected_path_topic;
  std::string base_frame = "base_link";
  std::size_t max_points = 2'000'000;
  /// The ROS 2 node the server shows on ros_discovery_info (`ros2 node list`): "/" + name.
  std::string node_name = "densemap_server";
  RosGidLayout gid_layout = RosGidLayout::kIronAndLater;
};

struct Ros2Counters {
  std::uint64_t received = 0;      // clouds taken from the rt/ topics
  std::uint64_t submitted = 0;     // handed to the pipeline with their transform
  std::uint64_t rejected = 0;      // malformed (by reason below)
  std::uint64_t no_transform = 0;  // dropped: no transform within tf_wait (or never possible)
  std::array<std::uint64_t, ros2::kCloudRejectCount> rejected_by_reason{};
  std::uint64_t non_finite_points = 0;  // NaN/Inf points dropped from accepted clouds
  std::uint64_t tf_rejected = 0;        // transforms refused (bad quaternion, cycle...)
  std::uint64_t maps_published = 0;     // map-topic rounds written
  std::string last_reject;
  /// Per cloud topic: writers matched now and refused for their QoS.
  std::vector<RosCloudTopicStatus> clouds;
};

/// The server's ROS 2 face (docs/ros2.md), one thread on the server's participant:
/// - sensor_msgs/PointCloud2 on each configured cloud topic, transformed into `world_frame`
///   with the TF buffer (rt/tf, rt/tf_static) at the cloud's stamp and submitted to the
///   pipeline as sensor-frame scans (sensor id = the topic name). With ros2.robots, each
///   robot's clouds are looked up in its own TF tree (<ns>/tf, <ns>/tf_static). A cloud whose
///   transform is not there yet waits up to tf_wait (at most max_waiting clouds; the oldest goes
///   first).
/// - octomap_msgs/Octomap, nav_msgs/OccupancyGrid and sensor_msgs/PointCloud2 of occupied
///   centres, transient-local, at most every publish_period_s and only after the map changed,
///   from state kept current per version (O(changed cells)), never a walk of the map per scan.
class Ros2Bridge {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<Ros2Bridge>> create(Ingest& ingest,
                                                                    const dds::Entity& participant,
                                                                    const Ros2Options& options);
  ~Ros2Bridge();
  Ros2Bridge(const Ros2Bridge&) = delete;
  Ros2Bridge& operator=(const Ros2Bridge&) = delete;

  void start();
  void stop();  // idempotent
  /// Called for every published version (on the pipeline's worker: only records it).
  void onVersion(const IntegrationResult& result, const std::shared_ptr<const MapView>& view);
  [[nodiscard]] Ros2Counters counters() const;

 private:
  struct Dds;
  struct Waiting;
  struct Topics;  // the bridge thread's state: TF buffer, waiting clouds, map-topic state
  Ros2Bridge(Ingest& ingest, const Ros2Options& options);
  void loop();
  void takeTransforms();
  /// One robot's transforms into its TF buffer; counts those refused into `refused`.
  void takeTransforms(std::size_t robot, std::uint64_t& refused);
  void takeClouds(std::size_t topic);
  /// A robot's corrected paths, as pose corrections of its cloud topics (after its clouds
  /// went to the ingest, so the corrections find their scans).
  void takePaths(std::size_t robot);
  /// A robot's cloud readers and TF readers (ns "" : the root's), attached to the wait set.
  [[nodiscard]] Expected<void> addRobot(const std::string& ns);
  /// ros2.robot_pattern: robots whose cloud publishers appeared since the last call.
  void discoverRobots();
  /// (Re)writes the server's ROS node announcement with its readers and writers.
  [[nodiscard]] Expected<void> announce();
  /// Submits what can be transformed now; drops what waited too long (or can never resolve).
  void resolveWaiting(std::chrono::steady_clock::time_point now);
  void publishMaps();
  void reject(ros2::CloudReject reason);

  Ingest& ingest_;
  Ros2Options options_;
  std::unique_ptr<Dds> dds_;
  std::unique_ptr<Topics> state_;
  std::atomic<bool> running_{false};
  std::thread thread_;

  std::mutex versions_mutex_;
  std::vector<std::uint64_t> pending_blocks_;
  std::shared_ptr<const MapView> latest_;

  mutable std::mutex counters_mutex_;
  Ros2Counters counters_;
  /// Guards Dds's cloud topics (the bridge thread adds robots; counters() reads them).
  mutable std::mutex topics_mutex_;
};

}  // namespace densemap::server
