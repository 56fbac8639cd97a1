#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <string_view>
#include <vector>

#include "densemap/geometry/chunk_runner.hpp"
#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/map/cell_change.hpp"
#include "densemap/traversal/scan_update.hpp"
#include "densemap/map/sensor_model.hpp"

namespace densemap {

enum class Backend { kGrid, kOctree };

[[nodiscard]] std::string_view backendName(Backend backend);


/// What applying one scan's update did to the map.
struct ApplyStats {
  std::size_t updated_cells = 0;  // cells the update touched (free + occupied candidates)
  std::size_t changed_cells = 0;  // cells whose log-odds changed or that became known
};

/// A block with fully-free cells (OccupancyMap::appendFullyFreeBlocks): its key and their mask.
struct FullyFreeBlock {
  std::uint64_t key = 0;
  block::BlockMask mask{};
};

/// A log-odds occupancy map at one resolution: the storage behind every integration method.
/// Each backend keeps OctoMap's per-cell semantics exactly (docs/architecture.md).
///
/// Thread-safety: single writer. `apply` runs its blocks through the map's ChunkRunner (serial
/// unless setRunner() gave another, such as tbbRunner() in the caller's task arena) but must
/// not run concurrently with any other call; const methods are safe to call concurrently with
/// each other.
class OccupancyMap {
 public:
  OccupancyMap(double resolution_m, const SensorModel& model)
      : grid_(resolution_m), model_(model) {}
  virtual ~OccupancyMap() = default;
  OccupancyMap(const OccupancyMap&) = delete;
  OccupancyMap& operator=(const OccupancyMap&) = delete;

  [[nodiscard]] virtual Backend backend() const = 0;
  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  [[nodiscard]] double resolution() const { return grid_.resolution(); }
  [[nodiscard]] const SensorModel& sensorModel() const { return model_; }
  /// What runs the map's per-block work (the runner must outlive the map).
  void setRunner(const ChunkRunner& runner) { runner_ = &runner; }
  [[nodiscard]] const ChunkRunner& runner() const { return *runner_; }

  /// Applies one scan under the update's rule (UpdateRule). When `changes` is
  /// given, the cells whose value changed (or became known) are appended to it.
  virtual ApplyStats apply(const ScanUpdate& update, CellChanges* changes = nullptr) = 0;

  /// Forgets every cell with min <= key <= max (per axis); appends them to `changes` as erased.
  /// Returns how many cells were erased.
  virtual std::size_t clearBox(const VoxelKey& min, const VoxelKey& max,
                               CellChanges* changes = nullptr) = 0;

  /// Log-odds of a cell; std::nullopt where the cell is unknown.
  [[nodiscard]] virtual std::optional<float> logOdds(const VoxelKey& key) const = 0;
  [[nodiscard]] std::optional<float> logOddsAt(const Point3f& point_world) const;

  /// Calls f(key, log_odds) once for every known cell at the finest resolution.
  virtual void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const = 0;

  /// Sets a cell's log-odds directly (loading snapshots, building maps in tests).
  virtual void setLogOdds(const VoxelKey& key, float log_odds) = 0;

  /// Appends to `out` every block in `box` with cells at the lower clamping bound (a free
  /// update cannot change them), once each, with its mask of those cells: the input of the
  /// culling region. One call per scan (a callback per block, through std::function, was a
  /// call per fully-free block of the box on every scan). The grid's cost follows the blocks in
  /// and near the box, not the map's size.
  virtual void appendFullyFreeBlocks(const block::BlockBox& box,
                                     std::vector<FullyFreeBlock>& out) const = 0;

  [[nodiscard]] virtual std::size_t knownCells() const = 0;
  /// Bytes held by the map's storage (approximate for the octree: OctoMap's own estimate).
  [[nodiscard]] virtual std::size_t memoryBytes() const = 0;
  virtual void clear() = 0;

 private:
  VoxelGrid grid_;
  SensorModel model_;
  const ChunkRunner* runner_ = &serialRunner();
};

}  // namespace densemap
