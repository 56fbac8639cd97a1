#include "densemap/planner/swept_volume.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "densemap/query/block_accessor.hpp"
#include "densemap/query/map_queries.hpp"

namespace densemap {

namespace {

using Vec3 = Eigen::Vector3d;

/// Squared distance from x to the closed box [lo, hi].
double pointBoxD2(const Vec3& x, const Vec3& lo, const Vec3& hi) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = x[a] < lo[a] ? lo[a] - x[a] : x[a] > hi[a] ? x[a] - hi[a] : 0.0;
    d2 += e * e;
  }
  return d2;
}

/// A key index for coordinate `c`, clamped to the key range.
int clampedKey(const VoxelGrid& grid, double c) {
  const double k = std::floor(c * grid.resolutionFactor()) + VoxelGrid::kMaxKey;
  return static_cast<int>(std::clamp(k, 0.0, 65535.0));
}

/// Keeps `found` as the earlier of itself and a conflict at `arc`.
void keepFirst(std::optional<SweptConflict>& found, const VoxelGrid& grid, const VoxelKey& key,
               double arc, std::size_t index) {
  if (found && found->arc_length <= arc) return;
  found = SweptConflict{key, grid.keyToPoint(key), arc, index};
}

/// The cells of the key box [lo, hi] that are not free, with their state: f(key, state).
template <class F>
void forEachNotFree(BlockAccessor& cells, const std::array<int, 3>& lo,
                    const std::array<int, 3>& hi, F&& f) {
  for (int z = lo[2]; z <= hi[2]; ++z) {
    for (int y = lo[1]; y <= hi[1]; ++y) {
      for (int x = lo[0]; x <= hi[0]; ++x) {
        const VoxelKey k{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                         static_cast<std::uint16_t>(z)};
        const CellState s = cellState(cells.logOdds(k));
        if (s != CellState::kFree) f(k, s);
      }
    }
  }
}

void finish(SweptVolumeResult& r) {
  if (r.occupied) {
    r.state = CellState::kOccupied;
    if (r.unknown && r.unknown->arc_length > r.occupied->arc_length) r.unknown.reset();
  } else if (r.unknown) {
    r.state = CellState::kUnknown;
  }
}

}  // namespace

SegmentBoxContact segmentBoxContact(const Vec3& a, const Vec3& b, const Vec3& lo, const Vec3& hi,
                                    double r2) {
  const Vec3 d = b - a;
  // Where the segment crosses a face plane of the box: f is one quadratic between them.
  std::array<double, 8> cuts{};
  std::size_t n = 0;
  cuts[n++] = 0.0;
  for (int k = 0; k < 3; ++k) {
    if (d[k] == 0.0) continue;
    for (const double bound : {lo[k], hi[k]}) {
      const double s = (bound - a[k]) / d[k];
      if (s > 0.0 && s < 1.0) cuts[n++] = s;
    }
  }
  cuts[n++] = 1.0;
  for (std::size_t i = 1; i < n; ++i) {  // insertion sort of at most 8
    for (std::size_t j = i; j > 0 && cuts[j - 1] > cuts[j]; --j) std::swap(cuts[j - 1], cuts[j]);
  }
  SegmentBoxContact out;
  out.min_d2 = pointBoxD2(a, lo, hi);
  double best_s = 0.0;
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const double s0 = cuts[i], s1 = cuts[i + 1];
    const Vec3 mid = a + 0.5 * (s0 + s1) * d;
    double num = 0.0, den = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double bound = mid[k] < lo[k] ? lo[k] : mid[k] > hi[k] ? hi[k] : mid[k];
      if (bound == mid[k]) continue;  // inside the slab on this axis
      num -= d[k] * (a[k] - bound);
      den += d[k] * d[k];
    }
    const double s = den > 0.0 ? std::clamp(num / den, s0, s1) : s0;
    for (const double c : {s, s1}) {
      const double f = pointBoxD2(a + c * d, lo, hi);
      if (f < out.min_d2) {
        out.min_d2 = f;
        best_s = c;
      }
    }
  }
  if (out.min_d2 > r2) return out;
  if (pointBoxD2(a, lo, hi) <= r2) {
    out.first_s = 0.0;
    return out;
  }
  // f is convex: it falls from above r2 at 0 to at most r2 at best_s; bisect the crossing,
  // keeping the upper end (a point within the radius).
  double below = 0.0, above = best_s;
  for (int it = 0; it < 60; ++it) {
    const double m = 0.5 * (below + above);
    (pointBoxD2(a + m * d, lo, hi) <= r2 ? above : below) = m;
  }
  out.first_s = above;
  return out;
}

Expected<double> checkPathRequest(const VoxelGrid& grid, std::span<const float> xyz,
                                  double radius_m, const SweptVolumeLimits& limits) {
  if (xyz.size() % 3 != 0) return makeError("path length is not a multiple of 3 (x y z each)");
  const std::size_t n = xyz.size() / 3;
  if (n == 0) return makeError("path has no vertices");
  if (n > limits.max_vertices) {
    return makeError("path of " + std::to_string(n) + " vertices, more than the " +
                     std::to_string(limits.max_vertices) + " allowed");
  }
  if (!std::isfinite(radius_m) || radius_m < 0 || radius_m > limits.max_radius_m) {
    return makeError("radius must be finite, 0 .. " + std::to_string(limits.max_radius_m) +
                     " m, got " + std::to_string(radius_m));
  }
  double length = 0.0;
  double cells = 0.0;
  const double res = grid.resolution();
  for (std::size_t i = 0; i < n; ++i) {
    const Point3f p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    if (!p.allFinite()) return makeError("vertex " + std::to_string(i) + " is NaN or Inf");
    if (!grid.pointToKey(p)) {
      return makeError("vertex " + std::to_string(i) + " is outside the map's range");
    }
    const double seg =
        i == 0 ? 0.0
               : (p.cast<double>() -
                  Point3f(xyz[3 * i - 3], xyz[3 * i - 2], xyz[3 * i - 1]).cast<double>())
                     .norm();
    length += seg;
    // Each piece (at most a cell long) covers a box of (1 + 2r/res + 2)^3 cells at most.
    const double side = 3.0 + 2.0 * radius_m / res;
    cells += std::max(1.0, std::ceil(seg / res)) * side * side * side;
  }
  if (length > limits.max_path_length_m) {
    return makeError("path of " + std::to_string(length) + " m, longer than the " +
                     std::to_string(limits.max_path_length_m) + " m allowed");
  }
  if (cells > limits.max_cells) {
    return makeError("path sweeps about " + std::to_string(static_cast<std::uint64_t>(cells)) +
                     " cells, more than the " +
                     std::to_string(static_cast<std::uint64_t>(limits.max_cells)) + " allowed");
  }
  return length;
}

Expected<SweptVolumeResult> checkPath(const MapView& view, std::span<const float> xyz,
                                      double radius_m, const SweptVolumeLimits& limits) {
  const VoxelGrid& grid = view.grid();
  const Expected<double> length = checkPathRequest(grid, xyz, radius_m, limits);
  if (!length) return std::unexpected(length.error());
  const double res = grid.resolution();
  const double half = 0.5 * res;
  // Conservative: a cell within a millionth of a cell of the radius counts as touched.
  const double reach = radius_m + 1e-6 * res;
  const double r2 = reach * reach;
  const std::size_t n = xyz.size() / 3;
  auto vertex = [&](std::size_t i) { return Vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]); };
  SweptVolumeResult r;
  BlockAccessor cells(view);
  double arc = 0.0;
  for (std::size_t seg = 0; seg < std::max<std::size_t>(n - 1, 1); ++seg) {
    const Vec3 a = vertex(seg);
    const Vec3 b = n == 1 ? a : vertex(seg + 1);
    const double len = (b - a).norm();
    const auto pieces = static_cast<std::size_t>(std::max(1.0, std::ceil(len / res)));
    for (std::size_t j = 0; j < pieces; ++j) {
      const double s0 = static_cast<double>(j) / static_cast<double>(pieces);
      const double s1 = static_cast<double>(j + 1) / static_cast<double>(pieces);
      const double arc0 = arc + s0 * len;
      // Nothing later on the path can come before the first occupied cell.
      if (r.occupied && arc0 > r.occupied->arc_length) break;
      const Vec3 pa = a + s0 * (b - a);
      const Vec3 pb = a + s1 * (b - a);
      std::array<int, 3> lo{}, hi{};
      for (int k = 0; k < 3; ++k) {
        lo[k] = clampedKey(grid, std::min(pa[k], pb[k]) - reach);
        hi[k] = clampedKey(grid, std::max(pa[k], pb[k]) + reach);
      }
      forEachNotFree(cells, lo, hi, [&](const VoxelKey& k, CellState s) {
        ++r.cells_tested;
        const Point3f c = grid.keyToPoint(k);
        const Vec3 centre = c.cast<double>();
        const auto contact = segmentBoxContact(pa, pb, centre - Vec3::Constant(half),
                                               centre + Vec3::Constant(half), r2);
        if (!contact.first_s) return;
        const double at = arc + (s0 + *contact.first_s * (s1 - s0)) * len;
        keepFirst(s == CellState::kOccupied ? r.occupied : r.unknown, grid, k, at, seg);
      });
    }
    arc += len;
    if (r.occupied && arc > r.occupied->arc_length) break;
  }
  r.length_m = *length;
  finish(r);
  return r;
}

Expected<SweptVolumeResult> checkBoxes(const MapView& view, std::span<const OrientedBox> boxes,
                                       const SweptVolumeLimits& limits) {
  const VoxelGrid& grid = view.grid();
  if (boxes.empty()) return makeError("no boxes");
  if (boxes.size() > limits.max_boxes) {
    return makeError(std::to_string(boxes.size()) + " boxes, more than the " +
                     std::to_string(limits.max_boxes) + " allowed");
  }
  const double res = grid.resolution();
  double cells = 0.0;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const OrientedBox& b = boxes[i];
    const bool finite =
        b.center.allFinite() && b.half_extents.allFinite() && b.rotation.coeffs().allFinite();
    if (!finite) return makeError("box " + std::to_string(i) + " has a NaN or Inf value");
    if ((b.half_extents.array() < 0).any() || b.half_extents.maxCoeff() > limits.max_radius_m) {
      return makeError("box " + std::to_string(i) + ": half extents must be 0 .. " +
                       std::to_string(limits.max_radius_m) + " m");
    }
    const float norm = b.rotation.norm();
    if (!(std::abs(norm - 1.0F) < 1e-3F)) {
      return makeError("box " + std::to_string(i) + ": rotation is not a unit quaternion");
    }
    if (!grid.pointToKey(b.center)) {
      return makeError("box " + std::to_string(i) + " is outside the map's range");
    }
    const double side = 3.0 + 2.0 * std::sqrt(3.0) * b.half_extents.maxCoeff() / res;
    cells += side * side * side;
  }
  if (cells > limits.max_cells) {
    return makeError("boxes cover about " + std::to_string(static_cast<std::uint64_t>(cells)) +
                     " cells, more than the " +
                     std::to_string(static_cast<std::uint64_t>(limits.max_cells)) + " allowed");
  }
  const double half = 0.5 * res;
  const double tol = 1e-6 * res;
  SweptVolumeResult r;
  BlockAccessor accessor(view);
  for (std::size_t i = 0; i < boxes.size() && !r.occupied; ++i) {
    const Eigen::Matrix3d rot = boxes[i].rotation.cast<double>().normalized().toRotationMatrix();
    const Vec3 e = boxes[i].half_extents.cast<double>();
    const Vec3 c = boxes[i].center.cast<double>();
    const Vec3 reach = rot.cwiseAbs() * e;  // the box's half extents in world axes
    std::array<int, 3> lo{}, hi{};
    for (int k = 0; k < 3; ++k) {
      lo[k] = clampedKey(grid, c[k] - reach[k] - tol);
      hi[k] = clampedKey(grid, c[k] + reach[k] + tol);
    }
    forEachNotFree(accessor, lo, hi, [&](const VoxelKey& k, CellState s) {
      ++r.cells_tested;
      const Vec3 t = grid.keyToPoint(k).cast<double>() - c;
      // Separating axes: the world's (the cell's) 3, the box's 3 and their 9 cross products.
      auto separated = [&](const Vec3& axis) {
        const double len = axis.norm();
        if (len < 1e-12) return false;
        const double cell = half * axis.cwiseAbs().sum();
        const double box = (rot.transpose() * axis).cwiseAbs().dot(e);
        return std::abs(t.dot(axis)) > cell + box + tol * len;
      };
      for (int a = 0; a < 3; ++a) {
        if (separated(Vec3::Unit(a)) || separated(rot.col(a))) return;
      }
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
          if (separated(Vec3::Unit(a).cross(rot.col(b)))) return;
        }
      }
      keepFirst(s == CellState::kOccupied ? r.occupied : r.unknown, grid, k, static_cast<double>(i),
                i);
    });
  }
  finish(r);
  return r;
}

void appendBoxFloats(const OrientedBox& box, std::vector<float>& out) {
  const Eigen::Quaternionf& q = box.rotation;
  out.insert(out.end(), {box.center.x(), box.center.y(), box.center.z(), box.half_extents.x(),
                         box.half_extents.y(), box.half_extents.z(), q.x(), q.y(), q.z(), q.w()});
}

Expected<std::vector<OrientedBox>> boxesFromFloats(std::span<const float> floats,
                                                   std::size_t max_boxes) {
  if (floats.size() % kBoxFloats != 0) {
    return makeError("boxes need 10 numbers each (centre, half extents, rotation x y z w), got " +
                     std::to_string(floats.size()));
  }
  const std::size_t n = floats.size() / kBoxFloats;
  if (n == 0 || n > max_boxes) {
    return makeError("1 to " + std::to_string(max_boxes) + " boxes, got " + std::to_string(n));
  }
  std::vector<OrientedBox> boxes(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* f = floats.data() + i * kBoxFloats;
    boxes[i].center = Point3f(f[0], f[1], f[2]);
    boxes[i].half_extents = Point3f(f[3], f[4], f[5]);
    boxes[i].rotation = Eigen::Quaternionf(f[9], f[6], f[7], f[8]);
  }
  return boxes;
}

}  // namespace densemap
