#pragma once

#include <octomap/OcTree.h>

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/map/sensor_model.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap::ros2 {

/// A 2D occupancy grid (nav_msgs/OccupancyGrid's content): row-major from the cell at
/// (origin_x, origin_y), -1 unknown, 0 free, 100 occupied.
struct GridImage {
  double resolution = 0.0;
  double origin_x = 0.0, origin_y = 0.0;
  std::uint32_t width = 0, height = 0;
  std::vector<std::int8_t> data;
};

/// What the ROS map topics publish, kept current from the versions' changed cells (O(changed
/// cells) per version, never a walk of the map):
/// - an OctoMap OcTree of the map (octomap_msgs/Octomap: `binaryData()`; occupied centres);
/// - per (x, y) column, how many occupied and free cells lie in the z band [min_z, max_z]
///   (the projected map: occupied if any occupied cell, free if only free, else unknown).
/// Building a message walks the tree or the columns once (the topics are rate-limited).
/// Thread-safety: one thread at a time.
class MapTopicsState {
 public:
  MapTopicsState(double resolution_m, double min_z_m, double max_z_m);

  /// Brings the state from version `base` (what it holds; null: empty) to `next`, given the
  /// blocks the versions between them wrote.
  void update(const MapView* base, const MapView& next, std::span<const std::uint64_t> blocks);

  /// OcTree::writeBinaryData of the map (occupied/free per leaf; a cell at log-odds exactly 0
  /// counts free, as densemap classifies it).
  /// Forgets everything (the next update starts from an empty state).
  void clear();

  [[nodiscard]] std::string binaryData() const;
  [[nodiscard]] std::vector<Point3f> occupiedCenters() const;
  [[nodiscard]] GridImage projectedGrid() const;
  [[nodiscard]] std::size_t cells() const { return cells_; }
  [[nodiscard]] const octomap::OcTree& tree() const { return tree_; }

  /// The reference projection of a whole view (for tests and a first publish).
  [[nodiscard]] static GridImage project(const MapView& view, double min_z_m, double max_z_m);

 private:
  struct Column {
    std::uint32_t occupied = 0, free = 0;
  };
  void apply(const VoxelKey& key, std::optional<float> before, std::optional<float> after);

  octomap::OcTree tree_;
  double resolution_;
  std::uint16_t min_z_key_, max_z_key_;
  std::unordered_map<std::uint32_t, Column> columns_;  // (x << 16) | y
  std::size_t cells_ = 0;
};

}  // namespace densemap::ros2
