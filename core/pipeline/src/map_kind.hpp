#pragma once

#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/raycast/integrator.hpp"

namespace densemap {

/// The map a pipeline integrates into, behind one interface: the pipeline calls
/// these and never asks which kind it holds. Every kind keeps an OccupancyMap that commands
/// act on and a GridMap readers see: the map itself when it is a grid, else a mirror that
/// follows its changes cell for cell (the octree backend). The log-odds kind integrates with
/// OctoMap's semantics (raycast, super rays, culling region); a kernel kind (AKIMap,
/// BGKOctoMap, BGKOctoMap-L, akimap_rays) keeps its alpha/beta evidence in the grid's own
/// block entries (one store: eviction, reset and erasure take both; beside an octree, in a
/// store of its own) and publishes logit(p) of the cells each scan reaches.
class MapKind {
 public:
  using Command = std::function<Expected<std::string>(OccupancyMap&, CellChanges&)>;
  using Keep = std::function<bool(const Point3f&)>;

  explicit MapKind(std::unique_ptr<OccupancyMap> map);
  virtual ~MapKind();
  MapKind(const MapKind&) = delete;
  MapKind& operator=(const MapKind&) = delete;

  /// Integrates one scan (world frame) taken from `origin`; the changed cells go to `changes`
  /// when given.
  virtual ScanStats integrate(const PointCloud& points_world, const Point3f& origin,
                              CellChanges* changes) = 0;
  /// Runs `command` on the map; its changes in `changes` (cells it erased lose their evidence).
  Expected<std::string> command(const Command& command, CellChanges& changes);
  /// Whether scans must report their changes (the mirror follows them).
  [[nodiscard]] bool needsChanges() const { return mirror_ != nullptr; }
  /// Before a version is published: the grid readers see catches up with `changes`.
  void beforePublish(const CellChanges& changes);
  /// The grid readers see (versioned: MapView::publish).
  [[nodiscard]] GridMap& published() { return *readable_; }
  /// Bytes held beyond the published grid (the octree's own when mirrored; else 0).
  [[nodiscard]] std::size_t ownBytes() const;
  /// Whether blocks can be evicted (the map is the grid itself).
  [[nodiscard]] bool canEvict() const { return mirror_ == nullptr; }
  /// Drops every block whose centre `keep` refuses (canEvict()), with any evidence.
  EvictStats evict(const Keep& keep, CellChanges* changes);
  /// A kernel kind's evidence (snapshots); none for the log-odds kind.
  [[nodiscard]] virtual std::optional<kernel::KernelEvidence> evidence() const {
    return std::nullopt;
  }
  /// Resumes a kernel kind's evidence; an error for another kind or method.
  [[nodiscard]] virtual Expected<void> restore(const kernel::KernelEvidence& evidence) = 0;
  /// Allocates the integrator's per-worker buffers before the first scan (log-odds kind).
  virtual void warmUp(double max_range_m) { (void)max_range_m; }
  /// The last scan's ray ends, one per point (log-odds kind; none for a kernel kind).
  [[nodiscard]] virtual std::span<const RayEnd> rayEnds() const { return {}; }

 protected:
  [[nodiscard]] OccupancyMap& map() { return *map_; }
  /// Cells a command erased: their evidence goes too (kernel kinds; a block the grid drops
  /// loses its evidence with it, BlockStore::drop).
  virtual void forget(const CellChanges& changes) { (void)changes; }

 private:
  std::unique_ptr<OccupancyMap> map_;
  std::unique_ptr<GridMap> mirror_;  // readers' copy when map_ is not a GridMap (octree)
  GridMap* readable_ = nullptr;      // map_ itself or mirror_
};

/// The log-odds map kind: OctoMap's semantics with `integrator`'s method and rule.
[[nodiscard]] std::unique_ptr<MapKind> makeLogOddsKind(std::unique_ptr<OccupancyMap> map,
                                                       const IntegratorOptions& integrator);
/// A dense kernel map kind with `options` (KernelOptions::defaults of its method, max range).
[[nodiscard]] std::unique_ptr<MapKind> makeKernelKind(std::unique_ptr<OccupancyMap> map,
                                                      const kernel::KernelOptions& options);

}  // namespace densemap
