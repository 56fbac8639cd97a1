#include "densemap/client/map_snapshot.hpp"

#include "densemap/query/map_queries.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/store/snapshot.hpp"
#include "map_snapshot_parts.hpp"

namespace densemap {

MapSnapshot::MapSnapshot(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MapSnapshot::MapSnapshot(MapSnapshot&&) noexcept = default;
MapSnapshot& MapSnapshot::operator=(MapSnapshot&&) noexcept = default;
MapSnapshot::~MapSnapshot() = default;

std::uint64_t MapSnapshot::version() const { return impl_->version; }

const std::vector<std::pair<std::string, std::int64_t>>& MapSnapshot::lastStamps() const {
  return impl_->last_stamps;
}

double MapSnapshot::resolution() const { return impl_->map->resolution(); }

std::size_t MapSnapshot::knownCells() const { return impl_->map->knownCells(); }

std::optional<float> MapSnapshot::logOdds(const Point3f& point_world) const {
  if (!point_world.allFinite()) return std::nullopt;
  return impl_->map->logOddsAt(point_world);
}

CellState MapSnapshot::state(const Point3f& point_world) const {
  return cellState(logOdds(point_world));
}

void MapSnapshot::forEachCell(
    const std::function<void(const Point3f& center, float log_odds)>& f) const {
  const VoxelGrid& grid = impl_->map->grid();
  impl_->map->forEachKnown([&](const VoxelKey& key, float v) { f(grid.keyToPoint(key), v); });
}

Expected<std::size_t> MapSnapshot::save(const std::string& path) const {
  const auto view = MapView::fromMap(*impl_->map, impl_->version);
  // The server's kind is not known here: a dense map's logit(p) may lie outside any clamp range.
  return saveSnapshot(*view, SensorModel{}, Backend::kGrid, path, nullptr,
                      SnapshotValues::kUnclamped);
}

}  // namespace densemap
