#pragma once

#include <filesystem>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/traversal/scan_update.hpp"
#include "densemap/sim/lidar_model.hpp"

namespace densemap {

/// The dense-oracle protocol's ground truth: what a dense, noise-free sensor observes
/// from the poses of a sparse sequence — occupied voxels where its rays end, free voxels where
/// they only pass. Unlike a scene's full ground truth it holds only what a sensor at those poses
/// could see, so a map is judged on filling holes between sparse beams, not on seeing through
/// walls.

/// A voxel the oracle labelled.
struct LabelledVoxel {
  VoxelKey key;
  bool occupied = false;
};

/// `base` made `factor` times as dense: factor - 1 beams interpolated between each pair of
/// adjacent beams, factor times the columns, no noise, no dropout.
[[nodiscard]] LidarModel denseLidar(const LidarModel& base, int factor);

/// Accumulates labels over scans at one resolution; a voxel ended in by any ray is occupied.
/// add() runs in the caller's task arena.
class OracleLabeller {
 public:
  explicit OracleLabeller(double resolution_m) : grid_(resolution_m) {}

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  void add(const PointCloud& points_world, const Point3f& origin_world);
  [[nodiscard]] std::vector<LabelledVoxel> labels() const;
  /// Writes the labels as an OctoMap .bt: occupied leaves at the upper clamp, free ones at the
  /// lower, everything else unknown.
  [[nodiscard]] Expected<void> write(const std::filesystem::path& path) const;

 private:
  VoxelGrid grid_;
  ScanUpdate labels_;
};

/// Where a dataset keeps its labels for one resolution: DIR/oracle_<resolution>.bt.
[[nodiscard]] std::filesystem::path oracleLabelsPath(const std::filesystem::path& dir,
                                                     double resolution_m);

/// Reads labels written by OracleLabeller::write; errors when the file is missing, broken or
/// of another resolution.
[[nodiscard]] Expected<std::vector<LabelledVoxel>> readOracleLabels(
    const std::filesystem::path& path, double resolution_m);

}  // namespace densemap
