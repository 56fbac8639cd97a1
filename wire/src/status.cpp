#include "densemap/wire/status.hpp"

#include "densemap_msgs.h"

namespace densemap::dds {
namespace {

char* lend(const std::string& s) { return const_cast<char*>(s.c_str()); }

}  // namespace

Expected<void> writeStatus(const Entity& writer, const ServerStatus& st) {
  densemap_msgs_Status s{};
  s.received = st.received;
  s.integrated = st.integrated;
  s.dropped = st.dropped;
  s.rejected = st.rejected;
  // Lent for the write: DDS serialises the sample and never writes through these.
  s.rejected_by_reason = borrowSequence<dds_sequence_unsigned_long_long>(
      std::span<const std::uint64_t>(st.rejected_by_reason));
  s.last_reject_reason = lend(st.last_reject_reason);
  s.latency_p50_ms = st.latency_p50_ms;
  s.latency_p99_ms = st.latency_p99_ms;
  s.known_cells = st.known_cells;
  s.map_version = st.map_version;
  s.memory_bytes = st.memory_bytes;
  s.uptime_s = st.uptime_s;
  s.rss_bytes = st.rss_bytes;
  s.evicted_blocks = st.evicted_blocks;
  s.evicted_cells = st.evicted_cells;
  s.decayed_cells = st.decayed_cells;
  s.snapshot_failures = st.snapshot_failures;
  s.last_snapshot_error = lend(st.last_snapshot_error);
  s.cpu_s = st.cpu_s;
  s.queries_answered = st.queries_answered;
  s.queries_rejected = st.queries_rejected;
  s.last_query_error = lend(st.last_query_error);
  std::vector<densemap_msgs_SensorStatus> sensors;
  sensors.reserve(st.sensors.size());
  for (const SensorCounters& sc : st.sensors) {
    sensors.push_back({lend(sc.sensor_id), sc.received, sc.integrated, sc.dropped, sc.rejected,
                       sc.seq_gaps, sc.latency_p50_ms, sc.latency_p99_ms});
  }
  s.sensors = borrowSequence<dds_sequence_densemap_msgs_SensorStatus>(sensors);
  s.ros_enabled = st.ros_enabled;
  s.ros_received = st.ros_received;
  s.ros_submitted = st.ros_submitted;
  s.ros_rejected = st.ros_rejected;
  s.ros_no_transform = st.ros_no_transform;
  s.ros_rejected_by_reason = borrowSequence<dds_sequence_unsigned_long_long>(
      std::span<const std::uint64_t>(st.ros_rejected_by_reason));
  s.ros_last_reject = lend(st.ros_last_reject);
  s.ros_maps_published = st.ros_maps_published;
  std::vector<densemap_msgs_RosCloudTopic> clouds;
  clouds.reserve(st.ros_clouds.size());
  for (const RosCloudTopicStatus& c : st.ros_clouds) {
    clouds.push_back(
        {lend(c.topic), c.matched_writers, c.incompatible_qos, lend(c.last_incompatible_policy)});
  }
  s.ros_clouds = borrowSequence<dds_sequence_densemap_msgs_RosCloudTopic>(clouds);
  s.foxglove_enabled = st.foxglove_enabled;
  s.foxglove_clients = st.foxglove_clients;
  s.foxglove_dropped_frames = st.foxglove_dropped_frames;
  s.foxglove_closed_clients = st.foxglove_closed_clients;
  s.foxglove_rejected = st.foxglove_rejected;
  const HistoryStatus& h = st.history;
  s.history_enabled = h.enabled;
  s.history_scans = h.scans;
  s.history_bytes = h.bytes;
  s.corrections = h.corrections;
  s.corrections_rejected = h.corrections_rejected;
  s.corrected_scans = h.corrected_scans;
  s.unmatched_poses = h.unmatched_poses;
  s.reintegrating = h.reintegrating;
  s.reintegration_done = h.reintegration_done;
  s.reintegration_total = h.reintegration_total;
  s.reintegrations = h.reintegrations;
  s.last_reintegration_ms_per_scan = h.last_ms_per_scan;
  s.last_reintegration_version = h.last_version;
  s.last_history_error = lend(h.last_error);
  return write(writer, &s);
}

ServerStatus statusFromWire(const densemap_msgs_Status& s) {
  ServerStatus out;
  out.received = s.received;
  out.integrated = s.integrated;
  out.dropped = s.dropped;
  out.rejected = s.rejected;
  out.rejected_by_reason.assign(s.rejected_by_reason._buffer,
                                s.rejected_by_reason._buffer + s.rejected_by_reason._length);
  out.last_reject_reason = text(s.last_reject_reason);
  out.latency_p50_ms = s.latency_p50_ms;
  out.latency_p99_ms = s.latency_p99_ms;
  out.known_cells = s.known_cells;
  out.map_version = s.map_version;
  out.memory_bytes = s.memory_bytes;
  out.uptime_s = s.uptime_s;
  out.rss_bytes = s.rss_bytes;
  out.evicted_blocks = s.evicted_blocks;
  out.evicted_cells = s.evicted_cells;
  out.decayed_cells = s.decayed_cells;
  out.snapshot_failures = s.snapshot_failures;
  out.last_snapshot_error = text(s.last_snapshot_error);
  out.cpu_s = s.cpu_s;
  out.queries_answered = s.queries_answered;
  out.queries_rejected = s.queries_rejected;
  out.last_query_error = text(s.last_query_error);
  for (std::uint32_t i = 0; i < s.sensors._length; ++i) {
    const auto& sc = s.sensors._buffer[i];
    out.sensors.push_back({.sensor_id = text(sc.sensor_id),
                           .received = sc.received,
                           .integrated = sc.integrated,
                           .dropped = sc.dropped,
                           .rejected = sc.rejected,
                           .seq_gaps = sc.seq_gaps,
                           .latency_p50_ms = sc.latency_p50_ms,
                           .latency_p99_ms = sc.latency_p99_ms});
  }
  out.ros_enabled = s.ros_enabled;
  out.ros_received = s.ros_received;
  out.ros_submitted = s.ros_submitted;
  out.ros_rejected = s.ros_rejected;
  out.ros_no_transform = s.ros_no_transform;
  out.ros_rejected_by_reason.assign(
      s.ros_rejected_by_reason._buffer,
      s.ros_rejected_by_reason._buffer + s.ros_rejected_by_reason._length);
  out.ros_last_reject = text(s.ros_last_reject);
  out.ros_maps_published = s.ros_maps_published;
  for (std::uint32_t i = 0; i < s.ros_clouds._length; ++i) {
    const auto& c = s.ros_clouds._buffer[i];
    out.ros_clouds.push_back({.topic = text(c.topic),
                              .matched_writers = c.matched_writers,
                              .incompatible_qos = c.incompatible_qos,
                              .last_incompatible_policy = text(c.last_incompatible_policy)});
  }
  out.foxglove_enabled = s.foxglove_enabled;
  out.foxglove_clients = s.foxglove_clients;
  out.foxglove_dropped_frames = s.foxglove_dropped_frames;
  out.foxglove_closed_clients = s.foxglove_closed_clients;
  out.foxglove_rejected = s.foxglove_rejected;
  out.history = {.enabled = s.history_enabled,
                 .scans = s.history_scans,
                 .bytes = s.history_bytes,
                 .corrections = s.corrections,
                 .corrections_rejected = s.corrections_rejected,
                 .corrected_scans = s.corrected_scans,
                 .unmatched_poses = s.unmatched_poses,
                 .reintegrating = s.reintegrating,
                 .reintegration_done = s.reintegration_done,
                 .reintegration_total = s.reintegration_total,
                 .reintegrations = s.reintegrations,
                 .last_ms_per_scan = s.last_reintegration_ms_per_scan,
                 .last_version = s.last_reintegration_version,
                 .last_error = text(s.last_history_error)};
  return out;
}

}  // namespace densemap::dds
