#pragma once

#include <octomap/OcTree.h>

#include <unordered_map>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// OctoMap's `OcTree` behind the common interface, for users who want OctoMap's structure
/// and files. OcTree is not thread-safe, so `apply` is serial; integrators still build the
/// update set in parallel.
class OctreeMap final : public OccupancyMap {
 public:
  OctreeMap(double resolution_m, const SensorModel& model);

  [[nodiscard]] Backend backend() const override { return Backend::kOctree; }
  ApplyStats apply(const ScanUpdate& update, CellChanges* changes = nullptr) override;
  /// Rebuilds the tree without the box: Debian's OctoMap asserts when inner nodes are deleted.
  std::size_t clearBox(const VoxelKey& min, const VoxelKey& max,
                       CellChanges* changes = nullptr) override;
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) const override;
  void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const override;
  void setLogOdds(const VoxelKey& key, float log_odds) override;
  /// After insertWithOctomap the first call rebuilds the masks (not concurrently with others).
  void appendFullyFreeBlocks(const block::BlockBox& box,
                             std::vector<FullyFreeBlock>& out) const override;
  [[nodiscard]] std::size_t knownCells() const override;
  [[nodiscard]] std::size_t memoryBytes() const override;
  void clear() override;

  [[nodiscard]] const octomap::OcTree& tree() const { return tree_; }

  /// The reference path: OctoMap's own `insertPointCloud(cloud, origin, max_range,
  /// lazy_eval=false, discretize=false)` on this tree. The oracle every method is held to.
  void insertWithOctomap(const PointCloud& points_world, const Point3f& origin_world,
                         double max_range_m);

 private:
  /// Keeps the fully-free masks in step with a cell's new value.
  void noteValue(const VoxelKey& key, float log_odds);
  /// Rebuilds fully_free_ from the tree after insertWithOctomap.
  void refreshFullyFree() const;

  octomap::OcTree tree_;
  // Cells at the lower clamping bound, per 8^3 block, maintained beside the tree (searching
  // the tree for them every scan would cost more than the culling saves).
  // insertWithOctomap bypasses apply(): the masks are rebuilt from the tree on next use.
  mutable std::unordered_map<std::uint64_t, block::BlockMask> fully_free_;
  mutable bool fully_free_stale_ = false;
};

/// Configures an OcTree's sensor model to `model` (shared by OctreeMap and the oracle).
void configureOcTree(octomap::OcTree& tree, const SensorModel& model);

/// Calls f(key, log_odds) for every finest-level cell an OcTree knows, expanding pruned leaves.
void forEachOcTreeCell(const octomap::OcTree& tree,
                       const std::function<void(const VoxelKey&, float)>& f);

}  // namespace densemap
