#include <cmath>
#include <thread>

#include "client_parts.hpp"
#include "densemap/query/version_delta.hpp"
#include "densemap/wire/delta_wire.hpp"
#include "densemap_msgs.h"
#include "map_snapshot_parts.hpp"

namespace densemap {

using namespace client_detail;

std::size_t Client::Impl::pollDeltas(const std::function<void(const DeltaInfo&)>& f) {
  if (dds_->delta_r.get() <= 0) return 0;
  return dds::takeAll<densemap_msgs_MapDelta>(dds_->delta_r, [&](const densemap_msgs_MapDelta& d) {
    DeltaInfo info;
    info.base_version = d.base_version;
    info.new_version = d.new_version;
    info.from_scan = d.from_scan;
    info.sensor_id = text(d.sensor_id);
    info.scan_seq = d.scan_seq;
    const VersionDelta delta = dds::cellsFrom(d);
    if (!delta.wellFormed()) return;  // dropped rather than misread
    info.changes = delta.changes();
    f(info);
  });
}

std::size_t Client::Impl::pollEvents(const std::function<void(const MapEventInfo&)>& f) {
  return dds::takeAll<densemap_msgs_MapEvent>(dds_->event_r, [&](const densemap_msgs_MapEvent& e) {
    MapEventInfo info;
    info.base_version = e.base_version;
    info.new_version = e.new_version;
    info.from_scan = e.from_scan;
    info.sensor_id = text(e.sensor_id);
    info.scan_seq = e.scan_seq;
    info.changed_cells = e.changed_cells;
    info.written_blocks = e.written_blocks;
    info.latency_ms = e.latency_ms;
    f(info);
  });
}

Expected<MapManifestInfo> Client::Impl::manifest() {
  if (auto ok = permitted(dds_->man_r, "reading the manifest"); !ok) {
    return std::unexpected(ok.error());
  }
  const auto deadline = Clock::now() + options_.timeout;
  std::optional<densemap_msgs_MapManifest> latest;
  while (!latest) {
    dds::forEachSample<densemap_msgs_MapManifest>(
        dds_->man_r, false, [&](const densemap_msgs_MapManifest& m) { latest = m; });
    if (latest) break;
    if (Clock::now() > deadline) return makeError("no map manifest from densemap-server");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  MapManifestInfo info{latest->version, latest->resolution, latest->known_cells, std::nullopt};
  if (latest->bounded) {
    const Point3f lo(static_cast<float>(latest->min_x), static_cast<float>(latest->min_y),
                     static_cast<float>(latest->min_z));
    const Point3f hi(static_cast<float>(latest->max_x), static_cast<float>(latest->max_y),
                     static_cast<float>(latest->max_z));
    if (!lo.allFinite() || !hi.allFinite() || (lo.array() > hi.array()).any()) {
      return makeError("the server's manifest holds a malformed box");
    }
    info.bounds = std::make_pair(lo, hi);
  }
  if (!(std::isfinite(info.resolution) && info.resolution > 0)) {
    return makeError("the server's manifest holds a malformed resolution");
  }
  return info;
}

Expected<MapSnapshot> Client::Impl::fetchMap(std::uint64_t min_version) {
  if (auto ok = permitted(dds_->man_r, "fetching the map"); !ok) return std::unexpected(ok.error());
  // 1. The manifest (1 Hz) says when the server's map has reached min_version.
  auto deadline = Clock::now() + options_.timeout;
  std::optional<densemap_msgs_MapManifest> manifest;
  while (!manifest || manifest->version < min_version) {
    dds::forEachSample<densemap_msgs_MapManifest>(
        dds_->man_r, false, [&](const densemap_msgs_MapManifest& m) { manifest = m; });
    if (manifest && manifest->version >= min_version) break;
    if (Clock::now() > deadline) {
      return makeError(manifest ? "the server's map did not reach version " +
                                      std::to_string(min_version) + " within the timeout"
                                : "no map manifest from densemap-server");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // 2. A tile reader for this fetch only (volatile: it must match before the request).
  auto reader = dds::createReader(dds_->participant, dds_->topics.tiles, dds::kTileQos);
  if (!reader) return std::unexpected(reader.error());
  for (dds_subscription_matched_status_t m{};
       dds_get_subscription_matched_status(reader->get(), &m) >= 0 && m.current_count == 0;) {
    if (Clock::now() > deadline) return makeError("the server's map/tiles writer did not match");
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the server's side of the match
  // 3. send-map; the reply comes after the server wrote every tile and says how many.
  const densemap_msgs_RequestId id{client_id_, next_request_};
  auto sent = commandReply(dds::CommandKind::kSendMap, {0, 0, 0}, {0, 0, 0}, {});
  if (!sent) return std::unexpected(sent.error());
  const std::uint64_t version = sent->sent_version, tile_count = sent->sent_tiles,
                      cell_count = sent->sent_cells;
  auto map = std::make_unique<GridMap>(manifest->resolution, SensorModel{});
  std::size_t tiles = 0, cells = 0;
  bool malformed = false;
  deadline = Clock::now() + options_.timeout;
  while (tiles < tile_count) {
    const std::size_t before = tiles;
    dds::takeAll<densemap_msgs_MapTile>(*reader, [&](const densemap_msgs_MapTile& t) {
      if (t.request.client_id != id.client_id || t.request.request_id != id.request_id) return;
      const VersionDelta d = dds::cellsFrom(t);
      if (!d.wellFormed()) {
        malformed = true;
        return;
      }
      map->applyChanges(d.changes());
      cells += d.size();
      ++tiles;
    });
    if (malformed) return makeError("malformed map tile from the server");
    if (tiles != before) deadline = Clock::now() + options_.timeout;  // progress: keep going
    if (tiles < tile_count && Clock::now() > deadline) {
      return makeError("map tiles stopped arriving: " + std::to_string(tiles) + " of " +
                       std::to_string(tile_count));
    }
    if (tiles < tile_count) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (cells != cell_count) {
    return makeError("map tiles hold " + std::to_string(cells) + " cells, the server sent " +
                     std::to_string(cell_count));
  }
  return MapSnapshotAccess::make(std::move(map), version, std::move(sent->sent_stamps));
}

}  // namespace densemap
