#include "densemap/planner/distance_slice.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace densemap {

namespace {

/// The key of height z (clamped into the key range).
int layerKey(const VoxelGrid& grid, double z_m) {
  const double k = std::floor(z_m * grid.resolutionFactor()) + VoxelGrid::kMaxKey;
  return static_cast<int>(std::clamp(k, 0.0, 65535.0));
}

}  // namespace

std::vector<std::array<float, 4>> distanceSlice(const DistanceField& field, double z_m) {
  const VoxelGrid grid(field.resolution());
  const int z = layerKey(grid, z_m);
  std::vector<std::array<float, 4>> out;
  field.forEachBlockInLayer(z >> 3, [&](std::uint64_t key, const auto& d2) {
    for (int i = (z & 7) << 6; i < ((z & 7) + 1) << 6; ++i) {
      if (DistanceField::isFar(d2[static_cast<std::size_t>(i)])) continue;
      const Point3f c = grid.keyToPoint(block::keyOf(key, i));
      out.push_back(
          {c.x(), c.y(), c.z(),
           static_cast<float>(std::sqrt(static_cast<double>(d2[static_cast<std::size_t>(i)])) *
                              field.resolution())});
    }
  });
  return out;
}

Costmap inflatedCostmap(const DistanceField& field, const MapView& view, double z_m,
                        double robot_radius_m) {
  const VoxelGrid& grid = view.grid();
  const int z = layerKey(grid, z_m);
  // The layer's blocks: the map's (known cells) and the field's (cells near obstacles).
  int bx0 = std::numeric_limits<int>::max(), by0 = bx0, bx1 = -1, by1 = -1;
  auto widen = [&](std::uint64_t key) {
    const auto c = block::coordsOf(key);
    bx0 = std::min(bx0, static_cast<int>(c[0]));
    by0 = std::min(by0, static_cast<int>(c[1]));
    bx1 = std::max(bx1, static_cast<int>(c[0]));
    by1 = std::max(by1, static_cast<int>(c[1]));
  };
  view.forEachBlock([&](std::uint64_t key, const VoxelBlock&) {
    if (static_cast<int>(block::coordsOf(key)[2]) == z >> 3) widen(key);
  });
  field.forEachBlockInLayer(z >> 3, [&](std::uint64_t key, const auto&) { widen(key); });
  Costmap m;
  m.resolution = grid.resolution();
  // The layer's extent follows the map (up to 65,536 cells an axis): past kMaxCostmapCells the
  // costmap is not built (an empty one), rather than allocated.
  if (bx1 < 0 ||
      static_cast<double>(bx1 - bx0 + 1) * (by1 - by0 + 1) * block::kEdge * block::kEdge >
          static_cast<double>(kMaxCostmapCells)) {
    return m;
  }
  m.width = static_cast<std::uint32_t>((bx1 - bx0 + 1) * block::kEdge);
  m.height = static_cast<std::uint32_t>((by1 - by0 + 1) * block::kEdge);
  const Point3f corner = grid.keyToPoint(
      VoxelKey{static_cast<std::uint16_t>(bx0 * 8), static_cast<std::uint16_t>(by0 * 8), 0});
  m.origin_x = corner.x() - 0.5 * m.resolution;
  m.origin_y = corner.y() - 0.5 * m.resolution;
  m.data.assign(static_cast<std::size_t>(m.width) * m.height, -1);
  const double cells = robot_radius_m / grid.resolution();
  const auto lethal = static_cast<std::uint32_t>(std::floor(cells * cells * (1 + 1e-9)));
  for (std::uint32_t y = 0; y < m.height; ++y) {
    for (std::uint32_t x = 0; x < m.width; ++x) {
      const VoxelKey k{static_cast<std::uint16_t>(bx0 * 8 + static_cast<int>(x)),
                       static_cast<std::uint16_t>(by0 * 8 + static_cast<int>(y)),
                       static_cast<std::uint16_t>(z)};
      std::int8_t& v = m.data[static_cast<std::size_t>(y) * m.width + x];
      const std::uint16_t d2 = field.distanceSquared(k);
      if (d2 != DistanceField::kFar && d2 <= lethal) {
        v = 100;
      } else if (view.logOdds(k)) {
        v = 0;
      }
    }
  }
  return m;
}

}  // namespace densemap
