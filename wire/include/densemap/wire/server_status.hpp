#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace densemap {

// A server's status as its clients see it: plain data, no DDS (the conversions to and from the
// wire are in densemap/wire/status.hpp).

/// What a mapping pipeline did with one sensor's scans (its server's status, per sensor).
struct SensorCounters {
  std::string sensor_id;
  std::uint64_t received = 0;    // submitted to the pipeline
  std::uint64_t integrated = 0;  // in the map
  std::uint64_t dropped = 0;     // overwritten in the latest-wins queue (integration behind)
  std::uint64_t rejected = 0;    // failed validation
  /// Sequence numbers skipped between consecutive received scans: scans lost before the
  /// pipeline saw them (e.g. overwritten in the DDS reader's history) or never sent.
  std::uint64_t seq_gaps = 0;
  std::uint64_t last_seq = 0;
  /// Received -> published of its last 256 integrated scans (0 before the first).
  double latency_p50_ms = 0.0;
  double latency_p99_ms = 0.0;

  bool operator==(const SensorCounters&) const = default;
};

/// One ROS 2 cloud topic the server reads: writers matched now, writers refused for their QoS.
struct RosCloudTopicStatus {
  std::string topic;
  std::uint32_t matched_writers = 0;
  std::uint64_t incompatible_qos = 0;    // writers refused so far (total)
  std::string last_incompatible_policy;  // e.g. "reliability"; empty: none

  bool operator==(const RosCloudTopicStatus&) const = default;
};

/// A map's history (server config history, docs/fleet.md): the scans kept for re-integration,
/// pose corrections, and their re-integration.
struct HistoryStatus {
  bool enabled = false;
  std::uint64_t scans = 0, bytes = 0;      // kept in the scan store
  std::uint64_t corrections = 0;           // received
  std::uint64_t corrections_rejected = 0;  // malformed, or not applicable
  std::uint64_t corrected_scans = 0;       // kept scans whose pose a correction replaced
  std::uint64_t unmatched_poses = 0;       // poses that named no kept scan
  bool reintegrating = false;              // a re-integration under way: done of total scans
  std::uint64_t reintegration_done = 0, reintegration_total = 0;
  std::uint64_t reintegrations = 0;  // swapped into the map
  double last_ms_per_scan = 0;       // the last one's re-integration time per scan
  std::uint64_t last_version = 0;    // the map version that swapped it in
  std::string last_error;

  bool operator==(const HistoryStatus&) const = default;
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
  std::uint64_t decayed_cells = 0;      // occupied cells map.decay made unknown
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
  /// The Foxglove WebSocket endpoint (server config foxglove): clients connected now, frames
  /// a client's full send queue did not take, clients closed for a stalled queue, and
  /// connections and client operations refused (over max_clients, bad handshake, bad frame).
  bool foxglove_enabled = false;
  std::uint64_t foxglove_clients = 0, foxglove_dropped_frames = 0, foxglove_closed_clients = 0,
                foxglove_rejected = 0;
  HistoryStatus history;

  bool operator==(const ServerStatus&) const = default;
};

}  // namespace densemap
