#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "densemap/io/sensor_counters.hpp"
#include "densemap/wire/dds.hpp"

// The IDL type (densemap_msgs.h, generated; not installed with the SDK).
struct densemap_msgs_Status;

namespace densemap {

/// One ROS 2 cloud topic the server reads: writers matched now, writers refused for their QoS.
struct RosCloudTopicStatus {
  std::string topic;
  std::uint32_t matched_writers = 0;
  std::uint64_t incompatible_qos = 0;   // writers refused so far (total)
  std::string last_incompatible_policy;  // e.g. "reliability"; empty: none

  bool operator==(const RosCloudTopicStatus&) const = default;
};

/// A server's status as densemap/status carries it (densemap_msgs.idl Status): built once by
/// the server from its counters, written and read by the conversions below only, for the server
/// and the client alike (one definition on each side of the wire).
struct ServerStatus {
  std::uint64_t received = 0, integrated = 0, dropped = 0, rejected = 0;
  std::vector<std::uint64_t> rejected_by_reason;
  std::string last_reject_reason;
  double latency_p50_ms = 0, latency_p99_ms = 0;
  std::uint64_t known_cells = 0, map_version = 0, memory_bytes = 0;
  double uptime_s = 0;
  std::uint64_t queries_answered = 0, queries_rejected = 0;
  std::string last_query_error;
  std::vector<SensorCounters> sensors;  // per sensor id (last_seq is not sent)
  std::uint64_t rss_bytes = 0;          // the server process's resident memory
  std::uint64_t evicted_blocks = 0;     // dropped by map.keep_radius_m / map.bounds
  std::uint64_t evicted_cells = 0;
  std::uint64_t snapshot_failures = 0;  // saves that failed (command, autosave, shutdown)
  std::string last_snapshot_error;
  double cpu_s = 0;  // and its CPU time since start
  /// The ROS 2 face (server config ros2): PointCloud2 clouds received, submitted with their
  /// transform, rejected as malformed (by reason), dropped for want of a transform.
  bool ros_enabled = false;
  std::uint64_t ros_received = 0, ros_submitted = 0, ros_rejected = 0, ros_no_transform = 0;
  std::vector<std::uint64_t> ros_rejected_by_reason;
  std::string ros_last_reject;
  std::uint64_t ros_maps_published = 0;
  std::vector<RosCloudTopicStatus> ros_clouds;  // per cloud topic (ros2.clouds)

  bool operator==(const ServerStatus&) const = default;
};

namespace dds {

/// Writes `status` on `writer` (densemap/status).
[[nodiscard]] Expected<void> writeStatus(const Entity& writer, const ServerStatus& status);
/// A received sample as a ServerStatus (every field; absent strings as empty).
[[nodiscard]] ServerStatus statusFromWire(const densemap_msgs_Status& sample);

}  // namespace dds
}  // namespace densemap
