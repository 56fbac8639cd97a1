#include "command_room.hpp"

#include <tuple>
#include <vector>

#include "densemap/query/map_queries.hpp"
#include "densemap/query/version_delta.hpp"
#include "densemap/server/export_path.hpp"
#include "densemap/wire/delta_wire.hpp"
#include "densemap/wire/topics.hpp"

namespace densemap::server {

void CommandRoom::answer() {
  // send-map: a task, so it does not hold up other commands.
  const auto send_map = [this](const densemap_msgs_RequestId& id) {
    tasks_.run([this, id] {
      const Expected<SentMap> sent = sendMap(id);
      if (!sent) {
        reply(id, std::unexpected(sent.error()));
        return;
      }
      reply(id,
            "version " + std::to_string(sent->version) + ": " + std::to_string(sent->tiles) +
                " tiles, " + std::to_string(sent->cells) + " cells",
            *sent);
    });
  };
  while (dds::takeOneWithInfo<densemap_msgs_CommandRequest>(
      endpoints_.map, [&](const densemap_msgs_CommandRequest& req, const dds_sample_info_t& info) {
        if (const auto w = replies_.writer(ReplyTopic::kCommand, req.id.client_id)) {
          replies_.awaitAsker(*w,
                              dds::participantOfWriter(endpoints_.map, info.publication_handle));
        }
        if (static_cast<dds::CommandKind>(req.kind) == dds::CommandKind::kSendMap) {
          send_map(req.id);
        } else {
          reply(req.id, makeError("densemap/map/request takes send-map only; command " +
                                  std::to_string(req.kind) + " goes to densemap/cmd/request"));
        }
      })) {
  }
  while (dds::takeOneWithInfo<densemap_msgs_CommandRequest>(
      endpoints_.commands,
      [&](const densemap_msgs_CommandRequest& req, const dds_sample_info_t& info) {
        if (const auto w = replies_.writer(ReplyTopic::kCommand, req.id.client_id)) {
          replies_.awaitAsker(
              *w, dds::participantOfWriter(endpoints_.commands, info.publication_handle));
        }
        const auto kind = static_cast<dds::CommandKind>(req.kind);
        if (kind == dds::CommandKind::kSendMap) {
          send_map(req.id);
          return;
        }
        Expected<std::string> outcome =
            kind == dds::CommandKind::kReset || kind == dds::CommandKind::kClearBox ? clear(req)
            : kind == dds::CommandKind::kSave
                ? save(req)
                : makeError("unknown command kind " + std::to_string(req.kind));
        reply(req.id, outcome);
      })) {
  }
}

Expected<std::string> CommandRoom::clear(const densemap_msgs_CommandRequest& req) {
  VoxelKey lo{0, 0, 0}, hi{65535, 65535, 65535};
  if (static_cast<dds::CommandKind>(req.kind) == dds::CommandKind::kClearBox) {
    const auto keys = boxKeys(ingest_.view()->grid(), toPoint(req.min), toPoint(req.max));
    if (!keys) return makeError("clear-bbox: " + keys.error().message);
    std::tie(lo, hi) = *keys;
  }
  auto future =
      ingest_.command([lo, hi](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
        return "erased " + std::to_string(map.clearBox(lo, hi, &changes)) + " cells";
      });
  return future.get();
}

Expected<std::string> CommandRoom::save(const densemap_msgs_CommandRequest& req) {
  // A named file goes into the configured export directory, never where the request says: a
  // client must not overwrite what the server's user may write.
  const std::string name = dds::text(req.path);
  Expected<std::filesystem::path> target = std::filesystem::path();
  if (!name.empty()) target = confineExportPath(export_dir_, name);
  if (!target) return std::unexpected(target.error());
  auto saved = saver_.save(*target);
  if (!saved) return std::unexpected(saved.error());
  return "saved " + std::to_string(*saved) + " bytes" +
         (name.empty() ? "" : " to " + target->string());
}

void CommandRoom::reply(const densemap_msgs_RequestId& id, const Expected<std::string>& outcome,
                        const SentMap& sent) {
  densemap_msgs_CommandReply rep{};
  rep.id = id;
  rep.map_version = ingest_.view()->version();
  rep.sent_version = sent.version;
  rep.sent_tiles = sent.tiles;
  rep.sent_cells = sent.cells;
  // Lent for the write: DDS serialises the sample and never writes through these.
  std::vector<densemap_msgs_SensorStamp> stamps;
  stamps.reserve(sent.last_stamps.size());
  for (const auto& [sensor, stamp] : sent.last_stamps) {
    stamps.push_back({const_cast<char*>(sensor.c_str()), stamp});
  }
  rep.sent_stamps = dds::borrowSequence<dds_sequence_densemap_msgs_SensorStamp>(stamps);
  const std::string error = outcome ? "" : outcome.error().message;
  const std::string detail = outcome ? *outcome : "";
  if (!outcome) stats_.refused(error);
  rep.status = outcome ? kOk : kInvalid;
  rep.error = const_cast<char*>(error.c_str());
  rep.detail = const_cast<char*>(detail.c_str());
  if (const auto w = replies_.writer(ReplyTopic::kCommand, id.client_id))
    (void)dds::write(*w, &rep);
}

Expected<SentMap> CommandRoom::sendMap(const densemap_msgs_RequestId& request) {
  // One version throughout: the tiles are a consistent copy of it.
  const ReturnFreeMemory trim;  // the tiles' buffers and the writer's copies until acked
  const Ingest::Latest latest = ingest_.latest();
  const auto& view = latest.view;
  const auto tiles = tilesOf(*view);
  std::size_t cells = 0;
  for (const auto& [id, blocks] : tiles) {
    VersionDelta t = cellsOf(*view, blocks);
    cells += t.cells.size();
    densemap_msgs_MapTile tile{};
    tile.request = request;
    tile.tile_id = id;
    tile.version = view->version();
    dds::borrowCells(tile, t);
    // Keep-all: a reader that does not keep up blocks the write; one that stopped ends it.
    if (auto ok = dds::write(endpoints_.tiles, &tile); !ok) {
      return makeError("send-map stopped after " + std::to_string(cells) +
                       " cells: " + ok.error().message);
    }
  }
  return SentMap{.version = view->version(),
                 .tiles = tiles.size(),
                 .cells = cells,
                 .last_stamps = latest.last_stamps};
}

}  // namespace densemap::server
