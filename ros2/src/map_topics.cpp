#include "densemap/ros2/map_topics.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/query/version_delta.hpp"

namespace densemap::ros2 {
namespace {

std::uint16_t zKey(const VoxelGrid& grid, double z_m) {
  constexpr double kLimit = 32767.0;
  const double cells = std::clamp(std::floor(z_m * grid.resolutionFactor()), -kLimit, kLimit);
  return static_cast<std::uint16_t>(static_cast<int>(cells) + 32768);
}

}  // namespace

MapTopicsState::MapTopicsState(double resolution_m, double min_z_m, double max_z_m)
    : tree_(resolution_m), resolution_(resolution_m) {
  const VoxelGrid grid(resolution_m);
  min_z_key_ = zKey(grid, min_z_m);
  max_z_key_ = zKey(grid, max_z_m);
  // No clamping: kernel maps' logit(p) goes in as it is (only occupied/free is published).
  tree_.setClampingThresMin(1e-9);
  tree_.setClampingThresMax(1.0 - 1e-9);
}

void MapTopicsState::apply(const VoxelKey& key, std::optional<float> before,
                           std::optional<float> after) {
  if (after) {
    tree_.setNodeValue(octomap::OcTreeKey(key.x, key.y, key.z), octomapClassValue(*after),
                       /*lazy_eval=*/true);
  }
  cells_ += (after ? 1 : 0);
  cells_ -= (before ? 1 : 0);
  if (key.z < min_z_key_ || key.z > max_z_key_) return;
  const std::uint32_t column = (std::uint32_t{key.x} << 16) | key.y;
  Column& c = columns_[column];
  if (before) (SensorModel::isOccupied(*before) ? c.occupied : c.free) -= 1;
  if (after) (SensorModel::isOccupied(*after) ? c.occupied : c.free) += 1;
  if (c.occupied == 0 && c.free == 0) columns_.erase(column);
}

void MapTopicsState::update(const MapView* base, const MapView& next,
                            std::span<const std::uint64_t> blocks) {
  bool erased = false;
  if (base == nullptr) {
    next.forEachKnown([&](const VoxelKey& k, float v) { apply(k, std::nullopt, v); });
  } else {
    const VersionDelta delta = diffVersions(*base, next, blocks);
    for (const CellChange& c : delta.changes()) {
      erased = erased || !c.known;
      apply(c.key, base->logOdds(c.key), c.known ? std::optional<float>(c.log_odds) : std::nullopt);
    }
  }
  if (erased) {
    // Cells become unknown only by command (reset, clear-bbox): rebuild the tree then. OctoMap
    // 1.9.7's deleteNode can leave a child array behind that its destructor asserts on.
    tree_.clear();
    next.forEachKnown([&](const VoxelKey& k, float v) {
      tree_.setNodeValue(octomap::OcTreeKey(k.x, k.y, k.z), octomapClassValue(v),
                         /*lazy_eval=*/true);
    });
  }
  tree_.updateInnerOccupancy();
  // Pruned, as octomap_server publishes it: eight equal children become their parent (a
  // later update of one cell expands it again, OcTree::setNodeValue does).
  tree_.prune();
}

void MapTopicsState::clear() {
  tree_.clear();
  columns_.clear();
  cells_ = 0;
}

std::string MapTopicsState::binaryData() const {
  std::ostringstream out;
  tree_.writeBinaryData(out);
  return out.str();
}

std::vector<Point3f> MapTopicsState::occupiedCenters() const {
  std::vector<Point3f> centers;
  const unsigned max_depth = tree_.getTreeDepth();
  for (auto it = tree_.begin_leafs(), end = tree_.end_leafs(); it != end; ++it) {
    if (!(it->getLogOdds() > 0.0F)) continue;
    // A pruned leaf stands for every cell under it: one centre each.
    const octomap::OcTreeKey k = it.getKey();
    const unsigned cells = 1U << (max_depth - it.getDepth());
    const unsigned base_x = k[0] & ~(cells - 1), base_y = k[1] & ~(cells - 1),
                   base_z = k[2] & ~(cells - 1);
    for (unsigned dz = 0; dz < cells; ++dz) {
      for (unsigned dy = 0; dy < cells; ++dy) {
        for (unsigned dx = 0; dx < cells; ++dx) {
          const octomap::point3d c =
              tree_.keyToCoord(octomap::OcTreeKey(static_cast<octomap::key_type>(base_x + dx),
                                                  static_cast<octomap::key_type>(base_y + dy),
                                                  static_cast<octomap::key_type>(base_z + dz)));
          centers.emplace_back(c.x(), c.y(), c.z());
        }
      }
    }
  }
  return centers;
}

namespace {

GridImage render(double resolution,
                 const std::vector<std::pair<std::uint32_t, std::int8_t>>& cells) {
  GridImage image;
  image.resolution = resolution;
  if (cells.empty()) return image;
  std::uint32_t min_x = UINT32_MAX, min_y = UINT32_MAX, max_x = 0, max_y = 0;
  for (const auto& [column, value] : cells) {
    const std::uint32_t x = column >> 16, y = column & 0xFFFF;
    min_x = std::min(min_x, x);
    min_y = std::min(min_y, y);
    max_x = std::max(max_x, x);
    max_y = std::max(max_y, y);
  }
  image.width = max_x - min_x + 1;
  image.height = max_y - min_y + 1;
  // Key k covers [(k - 32768) * res, (k - 32767) * res): the grid's origin is its lower corner.
  image.origin_x = (static_cast<double>(min_x) - 32768.0) * resolution;
  image.origin_y = (static_cast<double>(min_y) - 32768.0) * resolution;
  image.data.assign(std::size_t{image.width} * image.height, -1);
  for (const auto& [column, value] : cells) {
    const std::uint32_t x = (column >> 16) - min_x, y = (column & 0xFFFF) - min_y;
    image.data[std::size_t{y} * image.width + x] = value;
  }
  return image;
}

}  // namespace

GridImage MapTopicsState::projectedGrid() const {
  std::vector<std::pair<std::uint32_t, std::int8_t>> cells;
  cells.reserve(columns_.size());
  for (const auto& [column, c] : columns_) {
    cells.emplace_back(column, c.occupied > 0 ? std::int8_t{100} : std::int8_t{0});
  }
  return render(resolution_, cells);
}

GridImage MapTopicsState::project(const MapView& view, double min_z_m, double max_z_m) {
  const VoxelGrid& grid = view.grid();
  const std::uint16_t lo = zKey(grid, min_z_m), hi = zKey(grid, max_z_m);
  std::unordered_map<std::uint32_t, std::int8_t> columns;
  view.forEachKnown([&](const VoxelKey& k, float v) {
    if (k.z < lo || k.z > hi) return;
    std::int8_t& c =
        columns.try_emplace((std::uint32_t{k.x} << 16) | k.y, std::int8_t{0}).first->second;
    if (SensorModel::isOccupied(v)) c = 100;
  });
  return render(grid.resolution(),
                std::vector<std::pair<std::uint32_t, std::int8_t>>(columns.begin(), columns.end()));
}

}  // namespace densemap::ros2
