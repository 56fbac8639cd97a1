#pragma once

#include <octomap/OcTree.h>

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
  [[nodiscard]] std::size_t knownCells() const override;
  [[nodiscard]] std::size_t memoryBytes() const override { return tree_.memoryUsage(); }
  void clear() override { tree_.clear(); }

  [[nodiscard]] const octomap::OcTree& tree() const { return tree_; }

  /// The reference path: OctoMap's own `insertPointCloud(cloud, origin, max_range,
  /// lazy_eval=false, discretize=false)` on this tree. The oracle every method is held to.
  void insertWithOctomap(const PointCloud& points_world, const Point3f& origin_world,
                         double max_range_m);

 private:
  octomap::OcTree tree_;
};

/// Configures an OcTree's sensor model to `model` (shared by OctreeMap and the oracle).
void configureOcTree(octomap::OcTree& tree, const SensorModel& model);

/// Calls f(key, log_odds) for every finest-level cell an OcTree knows, expanding pruned leaves.
void forEachOcTreeCell(const octomap::OcTree& tree,
                       const std::function<void(const VoxelKey&, float)>& f);

}  // namespace densemap
