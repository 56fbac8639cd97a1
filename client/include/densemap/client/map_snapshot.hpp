#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/query/cell_state.hpp"

namespace densemap {

struct MapSnapshotAccess;

/// A read-only copy of a server's map at one version (Client::fetchMap). It owns its cells:
/// the server and later versions do not change it.
/// Thread-safety: every method is const and may be called from any number of threads.
class MapSnapshot {
 public:
  MapSnapshot(MapSnapshot&&) noexcept;
  MapSnapshot& operator=(MapSnapshot&&) noexcept;
  ~MapSnapshot();

  /// The server's map version this copy holds.
  [[nodiscard]] std::uint64_t version() const;
  /// The stamp of the last scan the server had integrated per sensor id at that version (at
  /// most 64 ids): a replica catching up from this copy skips the scans up to it.
  [[nodiscard]] const std::vector<std::pair<std::string, std::int64_t>>& lastStamps() const;
  /// Voxel edge, metres.
  [[nodiscard]] double resolution() const;
  /// Cells known (free or occupied).
  [[nodiscard]] std::size_t knownCells() const;
  /// The log-odds of the cell holding `point_world` (metres), or none where unknown or outside
  /// the map's addressable range.
  [[nodiscard]] std::optional<float> logOdds(const Point3f& point_world) const;
  [[nodiscard]] CellState state(const Point3f& point_world) const;
  /// Calls `f` with each known cell's centre (metres) and log-odds, block by block.
  void forEachCell(const std::function<void(const Point3f& center, float log_odds)>& f) const;
  /// Writes the map to `path`: `.dmap` (densemap's snapshot), `.bt` (OctoMap binary, occupied
  /// and free) or `.ot` (OctoMap with log-odds), atomically. Returns the bytes written.
  [[nodiscard]] Expected<std::size_t> save(const std::string& path) const;

 private:
  friend struct MapSnapshotAccess;
  struct Impl;
  explicit MapSnapshot(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace densemap
