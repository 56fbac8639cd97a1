#include "densemap/pipeline/map_queries.hpp"

#include <cmath>
#include <string>

#include "densemap/geometry/ray_traversal.hpp"

namespace densemap {

Expected<BoxQueryResult> queryBox(const MapView& view, const Point3f& min, const Point3f& max,
                                  std::size_t max_cells, std::size_t max_centers) {
  if (!min.allFinite() || !max.allFinite()) return makeError("box corner is NaN or Inf");
  if ((min.array() > max.array()).any()) return makeError("inverted box: min > max on some axis");
  const auto lo = view.grid().pointToKey(min);
  const auto hi = view.grid().pointToKey(max);
  if (!lo || !hi) return makeError("box outside the map's addressable range");
  const double cells =
      (static_cast<double>(hi->x) - lo->x + 1) * (static_cast<double>(hi->y) - lo->y + 1) *
      (static_cast<double>(hi->z) - lo->z + 1);
  if (cells > static_cast<double>(max_cells)) {
    return makeError("box of " + std::to_string(static_cast<long long>(cells)) +
                     " cells exceeds the limit of " + std::to_string(max_cells));
  }
  BoxQueryResult r;
  for (unsigned z = lo->z; z <= hi->z; ++z) {
    for (unsigned y = lo->y; y <= hi->y; ++y) {
      for (unsigned x = lo->x; x <= hi->x; ++x) {
        const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                         static_cast<std::uint16_t>(z)};
        switch (cellState(view.logOdds(k))) {
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
  return r;
}

Expected<RayQueryResult> castRay(const MapView& view, const Point3f& origin,
                                 const Point3f& direction, float max_range) {
  if (!origin.allFinite() || !direction.allFinite() || !std::isfinite(max_range)) {
    return makeError("ray origin, direction or range is NaN or Inf");
  }
  const float norm = direction.norm();
  if (norm < 1e-6F) return makeError("ray direction has zero length");
  if (max_range <= 0.0F || max_range > 1e4F) return makeError("ray range must be in (0, 10 km]");
  const Point3f end = origin + direction / norm * max_range;
  RayQueryResult r;
  std::optional<VoxelKey> first_hit;
  auto check = [&](const VoxelKey& k) {
    if (!first_hit && cellState(view.logOdds(k)) == CellState::kOccupied) first_hit = k;
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
