#include "densemap/query/map_queries.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "densemap/query/block_accessor.hpp"
#include "densemap/traversal/ray_traversal.hpp"

namespace densemap {

Expected<PointQueryResult> queryPoints(const MapView& view, std::span<const float> xyz,
                                       std::size_t max_points, const ChunkRunner& runner) {
  if (auto ok = checkPointCoordinates(xyz.size()); !ok) return std::unexpected(ok.error());
  const std::size_t n = xyz.size() / 3;
  if (n > max_points) {
    return makeError("more than " + std::to_string(max_points) + " query points");
  }
  PointQueryResult r;
  r.log_odds.assign(n, std::numeric_limits<float>::quiet_NaN());
  r.states.assign(n, 0);
  // Chunks on the runner; within a chunk neighbouring points mostly share a block.
  runner.run(n, 4096, [&](std::size_t begin, std::size_t end) {
    BlockAccessor cells(view);
    for (std::size_t i = begin; i != end; ++i) {
      const Point3f p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
      const auto key = p.allFinite() ? view.grid().pointToKey(p) : std::nullopt;
      const std::optional<float> v = key ? cells.logOdds(*key) : std::nullopt;
      if (v) r.log_odds[i] = *v;
      r.states[i] = static_cast<std::uint8_t>(cellState(v));
    }
  });
  return r;
}

Expected<void> checkPointCoordinates(std::size_t coordinates) {
  if (coordinates % 3 != 0) return makeError("point query length is not a multiple of 3");
  return {};
}

Expected<void> checkBox(const Point3f& min, const Point3f& max) {
  if (!min.allFinite() || !max.allFinite()) return makeError("box corner is NaN or Inf");
  if ((min.array() > max.array()).any()) return makeError("inverted box: min > max on some axis");
  return {};
}

std::optional<Point3f> unitDirection(const Point3f& direction) {
  // Scaled by its largest component first: the squares of a tiny (1e-30) or huge (1e30)
  // direction would underflow or overflow, though it has a direction all the same.
  const float largest = direction.cwiseAbs().maxCoeff();
  if (!(largest > 0.0F) || !std::isfinite(largest)) return std::nullopt;
  const Point3f scaled = direction / largest;
  return Point3f(scaled / scaled.norm());
}

Expected<void> checkRay(const Point3f& origin, const Point3f& direction, float max_range) {
  if (!origin.allFinite() || !direction.allFinite() || !std::isfinite(max_range)) {
    return makeError("ray origin, direction or range is NaN or Inf");
  }
  if (!unitDirection(direction)) return makeError("ray direction has zero length");
  if (max_range <= 0.0F || max_range > 1e4F) return makeError("ray range must be in (0, 10 km]");
  return {};
}

Expected<std::pair<VoxelKey, VoxelKey>> boxKeys(const VoxelGrid& grid, const Point3f& min,
                                                const Point3f& max) {
  if (auto ok = checkBox(min, max); !ok) return std::unexpected(ok.error());
  const auto lo = grid.pointToKey(min);
  const auto hi = grid.pointToKey(max);
  if (!lo || !hi) return makeError("box outside the map's addressable range");
  return std::pair(*lo, *hi);
}

Expected<BoxQueryResult> queryBox(const MapView& view, const Point3f& min, const Point3f& max,
                                  std::size_t max_cells, std::size_t max_centers) {
  const auto keys = boxKeys(view.grid(), min, max);
  if (!keys) return std::unexpected(keys.error());
  const VoxelKey* lo = &keys->first;
  const VoxelKey* hi = &keys->second;
  const double cells = (static_cast<double>(hi->x) - lo->x + 1) *
                       (static_cast<double>(hi->y) - lo->y + 1) *
                       (static_cast<double>(hi->z) - lo->z + 1);
  if (cells > static_cast<double>(max_cells)) {
    return makeError("box of " + std::to_string(static_cast<long long>(cells)) +
                     " cells exceeds the limit of " + std::to_string(max_cells));
  }
  // Block by block: one block lookup per 8^3 cells, cells in key order within the box.
  BoxQueryResult r;
  constexpr int kS = block::kShift;
  for (unsigned bz = lo->z >> kS; bz <= (hi->z >> kS); ++bz) {
    for (unsigned by = lo->y >> kS; by <= (hi->y >> kS); ++by) {
      for (unsigned bx = lo->x >> kS; bx <= (hi->x >> kS); ++bx) {
        const VoxelKey corner{static_cast<std::uint16_t>(bx << kS),
                              static_cast<std::uint16_t>(by << kS),
                              static_cast<std::uint16_t>(bz << kS)};
        const unsigned x0 = std::max<unsigned>(lo->x, corner.x),
                       x1 = std::min<unsigned>(hi->x, corner.x + block::kEdge - 1);
        const unsigned y0 = std::max<unsigned>(lo->y, corner.y),
                       y1 = std::min<unsigned>(hi->y, corner.y + block::kEdge - 1);
        const unsigned z0 = std::max<unsigned>(lo->z, corner.z),
                       z1 = std::min<unsigned>(hi->z, corner.z + block::kEdge - 1);
        const std::size_t cells_here = std::size_t{x1 - x0 + 1} * (y1 - y0 + 1) * (z1 - z0 + 1);
        const VoxelBlock* b = view.block(block::blockOf(corner));
        if (b == nullptr) {
          r.unknown += cells_here;
          continue;
        }
        for (unsigned z = z0; z <= z1; ++z) {
          for (unsigned y = y0; y <= y1; ++y) {
            for (unsigned x = x0; x <= x1; ++x) {
              const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                               static_cast<std::uint16_t>(z)};
              const int i = block::indexOf(k);
              const auto v = b->isKnown(i) ? std::optional<float>(b->log_odds[i]) : std::nullopt;
              switch (cellState(v)) {
                case CellState::kOccupied:
                  ++r.occupied;
                  if (r.occupied_centers.size() < max_centers) {
                    r.occupied_centers.push_back(view.grid().keyToPoint(k));
                  }
                  break;
                case CellState::kFree:
                  ++r.free;
                  break;
                case CellState::kUnknown:
                  ++r.unknown;
                  break;
              }
            }
          }
        }
      }
    }
  }
  return r;
}

Expected<void> forEachKnownInBox(const MapView& view, const Point3f& min, const Point3f& max,
                                 const std::function<void(const VoxelKey&, float)>& f) {
  const auto keys = boxKeys(view.grid(), min, max);
  if (!keys) return std::unexpected(keys.error());
  const VoxelKey lo = keys->first, hi = keys->second;
  constexpr int kS = block::kShift;
  const auto visit = [&](std::uint64_t block_key, const VoxelBlock& b) {
    for (int i = 0; i < block::kVoxels; ++i) {
      if (!b.isKnown(i)) continue;
      const VoxelKey k = block::keyOf(block_key, i);
      if (k.x < lo.x || k.x > hi.x || k.y < lo.y || k.y > hi.y || k.z < lo.z || k.z > hi.z)
        continue;
      f(k, b.log_odds[i]);
    }
  };
  const double box_blocks = (static_cast<double>(hi.x >> kS) - (lo.x >> kS) + 1) *
                            (static_cast<double>(hi.y >> kS) - (lo.y >> kS) + 1) *
                            (static_cast<double>(hi.z >> kS) - (lo.z >> kS) + 1);
  // Every block with contents holds at least one known cell.
  if (box_blocks > static_cast<double>(view.knownCells())) {
    const auto coord = [](std::uint16_t key) { return static_cast<std::uint32_t>(key >> kS); };
    const block::BlockBox blocks{{coord(lo.x), coord(lo.y), coord(lo.z)},
                                 {coord(hi.x), coord(hi.y), coord(hi.z)}};
    view.forEachBlock([&](std::uint64_t block_key, const VoxelBlock& b) {
      if (blocks.contains(block_key)) visit(block_key, b);
    });
    return {};
  }
  for (unsigned bz = lo.z >> kS; bz <= (hi.z >> kS); ++bz) {
    for (unsigned by = lo.y >> kS; by <= (hi.y >> kS); ++by) {
      for (unsigned bx = lo.x >> kS; bx <= (hi.x >> kS); ++bx) {
        const std::uint64_t block_key = block::blockOf(
            VoxelKey{static_cast<std::uint16_t>(bx << kS), static_cast<std::uint16_t>(by << kS),
                     static_cast<std::uint16_t>(bz << kS)});
        if (const VoxelBlock* b = view.block(block_key)) visit(block_key, *b);
      }
    }
  }
  return {};
}

Expected<RayQueryResult> castRay(const MapView& view, const Point3f& origin,
                                 const Point3f& direction, float max_range) {
  if (auto ok = checkRay(origin, direction, max_range); !ok) return std::unexpected(ok.error());
  const Point3f end = origin + *unitDirection(direction) * max_range;
  RayQueryResult r;
  std::optional<VoxelKey> first_hit;
  BlockAccessor cells(view);  // a ray's cells share blocks
  auto check = [&](const VoxelKey& k) {
    if (!first_hit && cellState(cells.logOdds(k)) == CellState::kOccupied) first_hit = k;
  };
  if (!traverseRay(view.grid(), origin, end, check)) {
    return makeError("ray leaves the map's addressable range");
  }
  if (!first_hit) check(*view.grid().pointToKey(end));
  if (first_hit) {
    r.hit = true;
    r.hit_center = view.grid().keyToPoint(*first_hit);
    r.distance = (r.hit_center - origin).norm();
  }
  return r;
}

}  // namespace densemap
