#include "free_bundles.hpp"
#include "radix_sort.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

namespace densemap::kernel {
namespace {

/// Each ray's hit number into buffers.hit_of (the stop it takes: rays with a length that are
/// not cut, in order; n + 1 entries) and whether it takes one into buffers.takes.
void numberHits(const PointCloud& points_world, const Eigen::Vector3d& origin, double max_range,
                FreeBundleBuffers& buffers) {
  const std::size_t n = points_world.size();
  std::vector<std::uint32_t>& hit_of = buffers.hit_of;
  hit_of.assign(n + 1, 0);
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
    hit_of[i + 1] = takesStop(points_world[i], origin, max_range) ? 1 : 0;
  });
  std::vector<std::uint32_t>& takes = buffers.takes;
  takes.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    takes[i] = hit_of[i + 1];
    hit_of[i + 1] += hit_of[i];
  }
}

}  // namespace

void freeExtents(const PointCloud& points_world, const Eigen::Vector3d& origin, double max_range,
                 std::span<const RayStop> stops, const CapsuleShape& shape,
                 const VoxelGrid* bundle_grid, FreeBundleBuffers& buffers,
                 std::vector<FreeExtent>& out) {
  out.clear();
  const bool bundle = bundle_grid != nullptr;
  const std::size_t n = points_world.size();
  numberHits(points_world, origin, max_range, buffers);
  const std::vector<std::uint32_t>& hit_of = buffers.hit_of;
  const std::vector<std::uint32_t>& takes = buffers.takes;
  // Rays by the cube of their hit (a cut ray, or one outside the addressable range, alone: the
  // key `alone`), rays in order within each, lone rays last; the cubes ranked in the window of
  // the max range around the origin.
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& rays = buffers.rays;
  std::uint64_t alone = std::uint64_t{1} << 48;
  if (bundle) {
    alone = sortByVoxel(
        n,
        [&](std::size_t i) {
          return takes[i] != 0 ? bundle_grid->pointToKey(points_world[i])
                               : std::optional<VoxelKey>();
        },
        KeyWindow::around(*bundle_grid, origin, max_range), rays, buffers.rays_other,
        buffers.radix_counts);
  } else {
    rays.resize(n);
    for (std::size_t i = 0; i < n; ++i) rays[i] = {alone, static_cast<std::uint32_t>(i)};
  }
  std::vector<std::size_t>& group_starts = buffers.group_starts;
  group_starts.clear();
  for (std::size_t p = 0; p < n; ++p) {
    if (p == 0 || rays[p].first != rays[p - 1].first || rays[p].first == alone) {
      group_starts.push_back(p);
    }
  }
  group_starts.push_back(n);
  const std::size_t groups = group_starts.size() - 1;
  // Each group's rays' tips then its capsule, in group order, in one pass: group g's slots
  // start at group_starts[g] + g, a slot per ray then one for the capsule. A ray without a tip,
  // or a group without free extent, leaves a hole (no length, weight 0: FreeTraversal skips
  // it), so no counting pass over every ray is needed. The order does not change the evidence
  // (FreeTraversal's sums are integers).
  const FreeExtent hole{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0.0, 0.0};
  out.resize(n + groups);
  tbb::parallel_for(std::size_t{0}, groups, [&](std::size_t g) {
    Eigen::Vector3d free_sum = Eigen::Vector3d::Zero();
    double frees = 0.0;
    std::size_t o = group_starts[g] + g;
    RayFreeSpace ray;
    for (std::size_t p = group_starts[g]; p < group_starts[g + 1]; ++p, ++o) {
      const std::uint32_t i = rays[p].second;
      std::size_t hit = hit_of[i];
      if (!rayFreeSpace(points_world[i], origin, max_range, stops, hit, ray)) {
        out[o] = hole;
        continue;
      }
      if (ray.extent > 0.0) {  // one piece, [origin, origin + extent along the ray]
        free_sum += origin + ray.extent * ray.direction;
        frees += 1.0;
      }
      out[o] = ray.has_tip ? FreeExtent{origin + ray.tip_from * ray.direction,
                                        origin + ray.tip_to * ray.direction, shape.tip_radius_m,
                                        shape.tip_weight}
                           : hole;
    }
    out[o] = frees > 0.0 ? FreeExtent{origin, free_sum / frees, shape.free_radius_m,
                                      shape.free_weight * frees}
                         : hole;
  });
}

namespace {

/// Bits 0..15 of v spread to every third bit (Morton order).
std::uint64_t spreadBits(std::uint64_t v) {
  v &= 0xffff;
  v = (v | (v << 16)) & 0x0000ff0000ffULL;
  v = (v | (v << 8)) & 0x00f00f00f00fULL;
  v = (v | (v << 4)) & 0x0c30c30c30c3ULL;
  v = (v | (v << 2)) & 0x249249249249ULL;
  return v;
}

/// A key's Morton code: the cubes of 2^b keys a side aligned on the keys (and so on the grid's
/// origin, keys being offset by 2^15) are the runs of equal code >> 3b.
std::uint64_t mortonOf(const VoxelKey& k) {
  return spreadBits(k.x) | (spreadBits(k.y) << 1) | (spreadBits(k.z) << 2);
}

}  // namespace

void freeExtentsTree(const PointCloud& points_world, const Eigen::Vector3d& origin,
                     double max_range, std::span<const RayStop> stops, const CapsuleShape& shape,
                     const VoxelGrid& bundle_grid, int levels, FreeBundleBuffers& buffers,
                     std::vector<FreeExtent>& out) {
  out.clear();
  levels = std::clamp(levels, 1, kMaxTreeLevels);
  const std::size_t n = points_world.size();
  numberHits(points_world, origin, max_range, buffers);
  const std::vector<std::uint32_t>& hit_of = buffers.hit_of;
  // Each ray by the Morton code of the cube of its end (its hit, or its cut point), shifted
  // up a bit whose set value marks a cut ray (a level-0 bundle of its own); rays of no length
  // or outside the addressable range last, alone.
  constexpr std::uint64_t kAlone = std::uint64_t{1} << 49;  // above every code << 1 | 1
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& rays = buffers.rays;
  rays.resize(n);
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
    const Eigen::Vector3d d = points_world[i].cast<double>() - origin;
    const double length = d.norm();
    std::uint64_t key = kAlone;
    if (length > 0.0) {
      const bool cut = max_range >= 0.0 && length > max_range;
      const Eigen::Vector3d end = cut ? Eigen::Vector3d(origin + d * (max_range / length))
                                      : Eigen::Vector3d(points_world[i].cast<double>());
      if (const auto voxel = bundle_grid.pointToKey(end.cast<float>())) {
        key = (mortonOf(*voxel) << 1) | (cut ? 1U : 0U);
      }
    }
    rays[i] = {key, static_cast<std::uint32_t>(i)};
  });
  radixSort(
      rays, buffers.rays_other, 50, [](const auto& pair) { return pair.first; },
      buffers.radix_counts);
  // Level-0 bundles: runs of one cube's hits; a cut or alone ray on its own.
  std::vector<std::size_t>& group_starts = buffers.group_starts;
  group_starts.clear();
  const auto single = [&](std::size_t p) {
    return rays[p].first == kAlone || (rays[p].first & 1U);
  };
  for (std::size_t p = 0; p < n; ++p) {
    if (p == 0 || rays[p].first != rays[p - 1].first || single(p)) group_starts.push_back(p);
  }
  group_starts.push_back(n);
  const std::size_t groups = group_starts.size() - 1;
  // Higher levels: runs of level-0 bundles whose cube codes agree above 3b bits (alone rays
  // each a run of their own), as indices of their first level-0 bundle.
  const auto code = [&](std::size_t g) { return rays[group_starts[g]].first >> 1; };
  const auto aloneGroup = [&](std::size_t g) { return rays[group_starts[g]].first == kAlone; };
  // Whether level-0 bundle g opens a bundle of level b (level 0: every one does).
  const auto opens = [&](std::size_t g, int b) {
    return b == 0 || g == 0 || aloneGroup(g) || aloneGroup(g - 1) ||
           (code(g) >> (3 * b)) != (code(g - 1) >> (3 * b));
  };
  std::vector<std::uint32_t>& level_starts = buffers.level_starts;
  level_starts.clear();
  std::vector<std::size_t> level_first(static_cast<std::size_t>(levels) + 2, 0);
  for (int b = 1; b <= levels; ++b) {
    level_first[static_cast<std::size_t>(b)] = level_starts.size();
    for (std::size_t g = 0; g < groups; ++g) {
      if (opens(g, b)) level_starts.push_back(static_cast<std::uint32_t>(g));
    }
    level_starts.push_back(static_cast<std::uint32_t>(groups));  // the level's end
  }
  level_first[static_cast<std::size_t>(levels) + 1] = level_starts.size();
  // Level 0: tips, and each bundle's sum of free ends and count.
  const FreeExtent hole{Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0.0, 0.0};
  std::vector<Eigen::Vector3d>& ends = buffers.ends;
  std::vector<double>& counts = buffers.counts;
  ends.assign(groups, Eigen::Vector3d::Zero());
  counts.assign(groups, 0.0);
  const std::size_t upper_slots = level_starts.size();
  out.assign(n + groups + upper_slots, hole);
  tbb::parallel_for(std::size_t{0}, groups, [&](std::size_t g) {
    std::size_t o = group_starts[g] + g;
    RayFreeSpace ray;
    for (std::size_t p = group_starts[g]; p < group_starts[g + 1]; ++p, ++o) {
      const std::uint32_t i = rays[p].second;
      std::size_t hit = hit_of[i];
      if (!rayFreeSpace(points_world[i], origin, max_range, stops, hit, ray)) continue;
      if (ray.extent > 0.0) {
        ends[g] += origin + ray.extent * ray.direction;
        counts[g] += 1.0;
      }
      if (ray.has_tip) {
        out[o] =
            FreeExtent{origin + ray.tip_from * ray.direction, origin + ray.tip_to * ray.direction,
                       shape.tip_radius_m, shape.tip_weight};
      }
    }
  });
  // From the top level down: each bundle's start (a fraction of the way to its mean end),
  // handed to its child where it has only one. start_of[g]: the start of the level-0 bundle
  // g's chain at the level being visited.
  std::vector<double> start_of(groups, 0.0);
  const auto fraction = [](int b) { return std::ldexp(1.0, -b); };
  const auto emit = [&](std::size_t slot, const Eigen::Vector3d& sum, double count, double from,
                        double to) {
    if (!(count > 0.0) || !(to > from)) return;
    const Eigen::Vector3d mean_end = sum / count;
    // The origin and the end themselves where a capsule starts or ends there (a lone ray's
    // capsule bit for bit as freeExtents makes it); joints are open, so that no voxel gets a
    // cap from the pieces on either side.
    out[slot] = FreeExtent{
        .from = from == 0.0 ? origin : Eigen::Vector3d(origin + from * (mean_end - origin)),
        .to = to == 1.0 ? mean_end : Eigen::Vector3d(origin + to * (mean_end - origin)),
        .radius_m = shape.free_radius_m,
        .weight = shape.free_weight * count,
        .open_from = from > 0.0,
        .open_to = to < 1.0};
  };
  for (int b = levels; b >= 1; --b) {
    const std::size_t first = level_first[static_cast<std::size_t>(b)];
    const std::size_t last = level_first[static_cast<std::size_t>(b) + 1] - 1;  // the end marker
    tbb::parallel_for(first, last, [&](std::size_t u) {
      const std::size_t g0 = level_starts[u], g1 = level_starts[u + 1];
      // Its start: the origin at the top level, else as its parent handed it down.
      const double start = b == levels ? 0.0 : start_of[g0];
      // Its children: the runs of level b - 1 within [g0, g1) (level 0: every bundle, a cut
      // ray's too, though it shares its cube's code).
      std::size_t children = 0;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      double count = 0.0;
      for (std::size_t g = g0; g < g1; ++g) {
        sum += ends[g];
        count += counts[g];
        children += g == g0 || opens(g, b - 1);
      }
      const double own_end = fraction(b);
      if (children > 1) emit(n + groups + u, sum, count, start, own_end);
      const double child_start = children > 1 ? own_end : start;
      for (std::size_t g = g0; g < g1; ++g) start_of[g] = child_start;
    });
  }
  tbb::parallel_for(std::size_t{0}, groups, [&](std::size_t g) {
    emit(group_starts[g + 1] + g, ends[g], counts[g], start_of[g], 1.0);
  });
}

}  // namespace densemap::kernel
