#pragma once

// The ROS 2 bridge's private state, shared by its two files: ros2_bridge.cpp (clouds and
// transforms in) and ros2_map_topics.cpp (the map topics out).
#include <chrono>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/ros2/tf_buffer.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "densemap/wire/dds.hpp"
#include "ros2_discovery.hpp"

namespace densemap::server {

/// One robot's TF topics (rt/tf and rt/tf_static, or <ns>/tf and <ns>/tf_static).
struct RobotTfReaders {
  dds::Entity tf_topic, tf_static_topic, tf_reader, tf_static_reader;
  dds::Entity path_topic, path_reader;  // its corrected path (ros2.corrected_path_topic)
};

struct Ros2Bridge::Dds {
  const dds::Entity* participant = nullptr;  // the server's; outlives the bridge
  std::vector<dds::Entity> cloud_topics, cloud_readers;
  std::vector<std::string> cloud_names;   // ROS names, the scans' sensor ids
  std::vector<std::string> cloud_frames;  // each topic's frame, as its last cloud named it
  std::vector<std::uint64_t> cloud_seq;
  std::vector<std::size_t> cloud_robot;  // the robot (index in robots) each cloud topic is of
  std::vector<RobotTfReaders> robots;    // one a robot; one for the root without ros2.robots
  std::vector<std::string> robot_names;  // their namespaces ("" : the root)
  dds::Entity publications;  // DCPSPublication, with ros2.robot_pattern: where robots appear
  bool full_logged = false;  // the robot bound was reached and said so
  dds::Entity octomap_topic, grid_topic, centers_topic;
  dds::Entity octomap_writer, grid_writer, centers_writer;
  /// The distance field's topics (a server with esdf): a slice and an inflated costmap.
  dds::Entity slice_topic, costmap_topic, slice_writer, costmap_writer;
  std::optional<dds::WaitSet> waitset;
  RosNodeAnnouncement node;  // the server on ros_discovery_info (`ros2 node list`)
};

struct Ros2Bridge::Waiting {
  std::string frame, sensor_id;
  std::size_t robot = 0;  // whose TF tree transforms it
  std::int64_t stamp_ns = 0;
  std::uint64_t seq = 0;
  ros2::DecodedCloud cloud;
  std::chrono::steady_clock::time_point received;
  bool waited = false;  // its transform was missing once: a backlog, submitted as room frees
};

struct Ros2Bridge::Topics {
  std::vector<ros2::TfBuffer> tf;  // one a robot, as Dds::robots
  std::deque<Waiting> waiting;
  std::unique_ptr<ros2::MapTopicsState> map;
  std::shared_ptr<const MapView> published;  // the version `map` holds
  /// The version last written to the map topics (kept while no one listens: a viewer that
  /// returns gets it from the writers' transient-local history, not a second copy).
  std::optional<std::uint64_t> written;
  std::optional<std::uint64_t> field_written;  // the same for the distance field's topics
  std::chrono::steady_clock::time_point next_publish = std::chrono::steady_clock::now();
};

}  // namespace densemap::server
