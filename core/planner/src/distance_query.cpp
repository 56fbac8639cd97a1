#include "densemap/planner/distance_query.hpp"

#include <cmath>
#include <limits>
#include <string>

#include "densemap/query/map_queries.hpp"

namespace densemap {

namespace {

/// The unknown cells of x in [cx - ext, cx + ext] on row (y, z) of `view`, placed as
/// nearestInRows wants them (bit 31 is cx). Cells outside the addressable range are unknown.
std::uint64_t unknownRow(const MapView& view, int cx, int y, int z, int ext) {
  if (y < 0 || y > 0xffff || z < 0 || z > 0xffff) return ~std::uint64_t{0};
  std::uint64_t bits = 0;
  for (int bx = (cx - ext) >> 3; bx <= (cx + ext) >> 3; ++bx) {
    std::uint64_t byte = 0xff;
    if (bx >= 0 && bx <= 0x1fff) {
      const std::uint64_t key = static_cast<std::uint64_t>(bx) |
                                (static_cast<std::uint64_t>(y >> 3) << 13) |
                                (static_cast<std::uint64_t>(z >> 3) << 26);
      if (const VoxelBlock* b = view.block(key); b != nullptr) {
        byte = ~(b->known[z & 7] >> ((y & 7) * 8)) & 0xffU;
      }
    }
    const int shift = bx * 8 - (cx - 31);
    if (shift >= 64) continue;
    bits |= shift >= 0 ? byte << shift : byte >> -shift;
  }
  return bits;
}

/// One cell's distance under the query's unknown policy: squared cells (kFar-like value
/// radius2 + 1 for none) and, when asked, the nearest obstacle's offset.
struct CellDistance {
  std::uint32_t d2;
  std::array<int, 3> offset{};
  bool has_offset = false;
};

CellDistance cellDistance(const DistanceField& field, const MapView& view, const VoxelKey& key,
                          bool unknown_as_occupied, bool want_offset) {
  const std::uint32_t none = field.radiusSquared() + 1;
  const std::uint16_t f = field.distanceSquared(key);
  CellDistance out{f == DistanceField::kFar ? none : std::uint32_t{f}};
  if (want_offset && out.d2 < none) {
    if (const auto n = field.nearestOccupied(key)) {
      out.offset = {n->x - key.x, n->y - key.y, n->z - key.z};
      out.has_offset = true;
    }
  }
  if (unknown_as_occupied && out.d2 > 0) {
    std::array<int, 3> off{};
    const CellCoord c = CellCoord::of(key);
    const std::uint32_t u = nearestInRows(
        c, out.d2, field.ballRows(),
        [&](int cx, int y, int z, int ext) { return unknownRow(view, cx, y, z, ext); }, &off);
    if (u < out.d2) {
      out.d2 = u;
      out.offset = off;
      out.has_offset = true;
    }
  }
  return out;
}

float metres(const DistanceField& field, std::uint32_t d2) {
  if (d2 > field.radiusSquared()) return static_cast<float>(field.maxDistance());
  return static_cast<float>(std::sqrt(static_cast<double>(d2)) * field.resolution());
}

}  // namespace

Expected<std::size_t> checkDistancePoints(const VoxelGrid& grid, std::span<const float> xyz,
                                          std::size_t max_points) {
  if (auto ok = checkPointCoordinates(xyz.size()); !ok) return std::unexpected(ok.error());
  const std::size_t n = xyz.size() / 3;
  if (n > max_points) {
    return makeError(std::to_string(n) + " points, more than the " + std::to_string(max_points) +
                     " a distance query may hold");
  }
  for (std::size_t i = 0; i < n; ++i) {
    const Point3f p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (!p.allFinite()) return makeError("point " + std::to_string(i) + " is NaN or Inf");
    if (!grid.pointToKey(p)) {
      return makeError("point " + std::to_string(i) + " is outside the map's range");
    }
  }
  return n;
}

Expected<DistanceQueryResult> queryDistances(const DistanceField& field, const MapView& view,
                                             std::span<const float> xyz,
                                             const DistanceQueryOptions& options,
                                             std::size_t max_points, const ChunkRunner& runner) {
  const auto n = checkDistancePoints(view.grid(), xyz, max_points);
  if (!n) return std::unexpected(n.error());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  DistanceQueryResult r;
  r.distances.assign(*n, 0.0F);
  r.gradients.assign(3 * *n, 0.0F);
  r.nearest.assign(3 * *n, nan);
  const VoxelGrid& grid = view.grid();
  const double res = grid.resolution();
  runner.run(*n, 1024, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i != end; ++i) {
      const Point3f p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
      const VoxelKey key = *grid.pointToKey(p);
      const bool want_offset = options.nearest || !options.interpolate;
      const CellDistance c =
          cellDistance(field, view, key, options.unknown_as_occupied, want_offset);
      if (c.has_offset) {
        const VoxelKey o{static_cast<std::uint16_t>(key.x + c.offset[0]),
                         static_cast<std::uint16_t>(key.y + c.offset[1]),
                         static_cast<std::uint16_t>(key.z + c.offset[2])};
        const Point3f centre = grid.keyToPoint(o);
        if (options.nearest) {
          for (int a = 0; a < 3; ++a) r.nearest[3 * i + a] = centre[a];
        }
      }
      if (!options.interpolate) {
        r.distances[i] = metres(field, c.d2);
        if (c.has_offset && c.d2 > 0) {
          const double len = std::sqrt(static_cast<double>(c.d2));
          for (int a = 0; a < 3; ++a) {
            r.gradients[3 * i + a] = static_cast<float>(-c.offset[a] / len);
          }
        }
        continue;
      }
      // Trilinear between the cell centres around p: u is p in cell units from the centre of
      // key 0 (so floor(u) is the lower corner's key).
      std::array<int, 3> lo{};
      std::array<double, 3> t{};
      for (int a = 0; a < 3; ++a) {
        const double u = static_cast<double>(p[a]) / res + VoxelGrid::kMaxKey - 0.5;
        lo[a] = static_cast<int>(std::floor(u));
        t[a] = u - lo[a];
      }
      std::array<double, 8> d{};
      for (int k = 0; k < 8; ++k) {
        CellCoord cc{lo[0] + (k & 1), lo[1] + ((k >> 1) & 1), lo[2] + ((k >> 2) & 1)};
        if (!cc.inRange()) {
          d[k] = options.unknown_as_occupied ? 0.0 : field.maxDistance();
          continue;
        }
        d[k] = metres(field,
                      cellDistance(field, view, cc.key(), options.unknown_as_occupied, false).d2);
      }
      auto lerp = [](double a, double b, double s) { return a + (b - a) * s; };
      const double x00 = lerp(d[0], d[1], t[0]), x10 = lerp(d[2], d[3], t[0]);
      const double x01 = lerp(d[4], d[5], t[0]), x11 = lerp(d[6], d[7], t[0]);
      const double y0 = lerp(x00, x10, t[1]), y1 = lerp(x01, x11, t[1]);
      r.distances[i] = static_cast<float>(lerp(y0, y1, t[2]));
      // The interpolant's partial derivatives (per metre).
      const double gx =
          lerp(lerp(d[1] - d[0], d[3] - d[2], t[1]), lerp(d[5] - d[4], d[7] - d[6], t[1]), t[2]);
      const double gy = lerp(x10 - x00, x11 - x01, t[2]);
      const double gz = y1 - y0;
      r.gradients[3 * i] = static_cast<float>(gx / res);
      r.gradients[3 * i + 1] = static_cast<float>(gy / res);
      r.gradients[3 * i + 2] = static_cast<float>(gz / res);
    }
  });
  return r;
}

Expected<DistanceBox> exportDistanceBox(const DistanceField& field, const MapView& view,
                                        const Point3f& min, const Point3f& max,
                                        bool unknown_as_occupied, std::size_t max_cells) {
  const auto keys = boxKeys(view.grid(), min, max);
  if (!keys) return std::unexpected(keys.error());
  DistanceBox box;
  box.min = keys->first;
  box.max = keys->second;
  double cells = 1;
  for (int a = 0; a < 3; ++a) {
    box.size[a] = static_cast<std::uint32_t>(box.max[a] - box.min[a] + 1);
    cells *= box.size[a];
  }
  if (cells > static_cast<double>(max_cells)) {
    return makeError("distance box of " + std::to_string(static_cast<std::uint64_t>(cells)) +
                     " cells, more than the " + std::to_string(max_cells) + " allowed");
  }
  box.distances.resize(static_cast<std::size_t>(cells));
  std::size_t i = 0;
  for (std::uint32_t z = 0; z < box.size[2]; ++z) {
    for (std::uint32_t y = 0; y < box.size[1]; ++y) {
      for (std::uint32_t x = 0; x < box.size[0]; ++x) {
        const VoxelKey k{static_cast<std::uint16_t>(box.min.x + x),
                         static_cast<std::uint16_t>(box.min.y + y),
                         static_cast<std::uint16_t>(box.min.z + z)};
        box.distances[i++] =
            metres(field, cellDistance(field, view, k, unknown_as_occupied, false).d2);
      }
    }
  }
  return box;
}

}  // namespace densemap
