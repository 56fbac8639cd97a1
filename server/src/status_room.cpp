#include "status_room.hpp"

#include "densemap/wire/status.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>

#include "densemap/io/process_usage.hpp"
#include "densemap_msgs.h"

namespace densemap::server {

std::vector<std::string> otherServers(const dds::Entity& participant,
                                      const dds::Entity& status_probe) {
  dds_guid_t own{};
  (void)dds_get_guid(participant.get(), &own);
  std::vector<dds_instance_handle_t> handles(16);
  dds_return_t n = dds_get_matched_publications(status_probe.get(), handles.data(), handles.size());
  if (n > static_cast<dds_return_t>(handles.size())) {
    handles.resize(static_cast<std::size_t>(n));
    n = dds_get_matched_publications(status_probe.get(), handles.data(), handles.size());
  }
  std::vector<std::string> others;
  for (dds_return_t i = 0; i < std::min<dds_return_t>(n, handles.size()); ++i) {
    dds_builtintopic_endpoint_t* e =
        dds_get_matched_publication_data(status_probe.get(), handles[i]);
    if (e == nullptr) continue;
    const bool mine = std::equal(std::begin(e->participant_key.v), std::end(e->participant_key.v),
                                 std::begin(own.v));
    if (!mine) {
      char guid[40];
      const auto& v = e->participant_key.v;
      std::snprintf(guid, sizeof guid, "%02x%02x%02x%02x:%02x%02x%02x%02x:%02x%02x%02x%02x", v[0],
                    v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9], v[10], v[11]);
      others.emplace_back(guid);
    }
    dds_builtintopic_free_endpoint(e);
  }
  return others;
}

void StatusRoom::publish() {
  // A server that appears later (a network partition healed, a second one started with checks
  // bypassed): said in the log once a minute; clients would see two maps.
  if (const auto now = std::chrono::steady_clock::now(); now >= next_alone_check_) {
    next_alone_check_ = now + std::chrono::seconds(60);
    if (const auto others = otherServers(participant_, status_probe_); !others.empty()) {
      spdlog::error("another densemap-server (participant {}) runs on DDS domain {}",
                    others.front(), domain_id_);
    }
  }
  const PipelineCounters c = ingest_.counters();
  const auto view = ingest_.view();
  ServerStatus s;
  s.received = c.received;
  s.integrated = c.integrated;
  s.dropped = c.dropped;
  s.rejected = c.rejected;
  s.rejected_by_reason.assign(c.rejected_by_reason.begin(), c.rejected_by_reason.end());
  s.last_reject_reason = c.last_reject_reason;
  s.latency_p50_ms = c.latency_p50_ms;
  s.latency_p99_ms = c.latency_p99_ms;
  s.known_cells = view->knownCells();
  s.map_version = view->version();
  s.memory_bytes = view->memoryBytes();
  s.uptime_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  const ProcessUsage usage = processUsage();
  s.rss_bytes = usage.rss_bytes;
  s.cpu_s = usage.cpu_s;
  s.evicted_blocks = c.evicted_blocks;
  s.evicted_cells = c.evicted_cells;
  s.decayed_cells = c.decayed_cells;
  s.history = c.history;
  s.snapshot_failures = sources_.snapshots.failures();
  s.last_snapshot_error = sources_.snapshots.lastError();
  s.queries_answered = sources_.requests.answeredCount();
  s.queries_rejected = sources_.requests.refusedCount();
  s.last_query_error = sources_.requests.lastError();
  s.sensors = c.sensors;
  const Ros2Counters ros = sources_.ros2 != nullptr ? sources_.ros2->counters() : Ros2Counters{};
  s.ros_enabled = sources_.ros2 != nullptr;
  s.ros_received = ros.received;
  s.ros_submitted = ros.submitted;
  s.ros_rejected = ros.rejected;
  s.ros_no_transform = ros.no_transform;
  s.ros_rejected_by_reason.assign(ros.rejected_by_reason.begin(), ros.rejected_by_reason.end());
  s.ros_last_reject = ros.last_reject;
  s.ros_maps_published = ros.maps_published;
  s.ros_clouds = ros.clouds;
  if (sources_.foxglove != nullptr) {
    const FoxgloveRoom::Counters f = sources_.foxglove->counters();
    s.foxglove_enabled = true;
    s.foxglove_clients = f.clients;
    s.foxglove_dropped_frames = f.dropped_frames;
    s.foxglove_closed_clients = f.closed_clients;
    s.foxglove_rejected = f.rejected;
    sources_.foxglove->onStatus(s);
  }
  (void)dds::writeStatus(writer_, s);
}

}  // namespace densemap::server
