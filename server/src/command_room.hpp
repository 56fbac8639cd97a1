#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "densemap/server/ingest.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap_msgs.h"
#include "replies.hpp"
#include "request_tasks.hpp"
#include "snapshot_saver.hpp"

namespace densemap::server {

/// What send-map wrote: its command reply's counts (a fetch waits for that many tiles and
/// cells of that version).
struct SentMap {
  std::uint64_t version = 0, tiles = 0, cells = 0;
  SensorStamps last_stamps;  // the last integrated scan's stamp per sensor id at `version`
};

/// Commands: reset, clear-bbox and save (densemap/cmd/request; they wait for the pipeline's
/// worker), and send-map (densemap/map/request, or cmd/request: a task that writes one
/// version's tiles to the asker, keep-all and flow-controlled).
class CommandRoom {
 public:
  struct Endpoints {
    const dds::Entity& commands;  // densemap/cmd/request
    const dds::Entity& map;       // densemap/map/request (send-map only)
    const dds::Entity& tiles;     // densemap/map/tiles
  };
  /// `export_dir`: where a named save goes (exportDirectory()).
  CommandRoom(Ingest& ingest, Endpoints endpoints, ReplyWriters& replies, RequestTasks& tasks,
              RequestStats& stats, SnapshotSaver& saver, std::filesystem::path export_dir)
      : ingest_(ingest),
        endpoints_(endpoints),
        replies_(replies),
        tasks_(tasks),
        stats_(stats),
        saver_(saver),
        export_dir_(std::move(export_dir)) {}

  /// Answers the commands waiting (service thread).
  void answer();

 private:
  /// reset (the whole map) or clear-bbox (its box), through the ingest's command queue.
  Expected<std::string> clear(const densemap_msgs_CommandRequest& req);
  /// save: the snapshot, or a named file confined to snapshot.export_dir.
  Expected<std::string> save(const densemap_msgs_CommandRequest& req);
  void reply(const densemap_msgs_RequestId& id, const Expected<std::string>& outcome,
             const SentMap& sent = {});
  /// Writes the latest version's tiles for `request` (send-map); returns what it wrote.
  Expected<SentMap> sendMap(const densemap_msgs_RequestId& request);

  Ingest& ingest_;
  Endpoints endpoints_;
  ReplyWriters& replies_;
  RequestTasks& tasks_;
  RequestStats& stats_;
  SnapshotSaver& saver_;
  std::filesystem::path export_dir_;
};

}  // namespace densemap::server
