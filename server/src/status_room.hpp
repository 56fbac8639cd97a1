#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "densemap/wire/dds.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "foxglove_room.hpp"
#include "request_tasks.hpp"
#include "snapshot_saver.hpp"

namespace densemap::server {

/// Participants other than `participant` that write densemap/status (other servers), as seen
/// by `status_probe` (a reader of densemap/status).
[[nodiscard]] std::vector<std::string> otherServers(const dds::Entity& participant,
                                                    const dds::Entity& status_probe);

/// densemap/status at 1 Hz: the pipeline's counters, the map, the process, the requests, the
/// snapshots and the ROS 2 face; and, once a minute, whether another server has appeared.
class StatusRoom {
 public:
  struct Sources {
    const RequestStats& requests;
    const SnapshotSaver& snapshots;
    const Ros2Bridge* ros2;  // null: ROS 2 off
    FoxgloveRoom* foxglove;  // null: the Foxglove endpoint is off (else it gets each status)
  };
  StatusRoom(Ingest& ingest, const dds::Entity& writer, const dds::Entity& participant,
             const dds::Entity& status_probe, std::uint32_t domain_id, Sources sources)
      : ingest_(ingest),
        writer_(writer),
        participant_(participant),
        status_probe_(status_probe),
        domain_id_(domain_id),
        sources_(sources) {}

  /// Publish thread.
  void publish();

 private:
  Ingest& ingest_;
  const dds::Entity& writer_;
  const dds::Entity& participant_;
  const dds::Entity& status_probe_;
  std::uint32_t domain_id_;
  Sources sources_;
  std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point next_alone_check_{};
};

}  // namespace densemap::server
