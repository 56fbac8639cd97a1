#include "free_bundles.hpp"
#include "radix_sort.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <utility>

namespace densemap::kernel {
int bundleLevel(double range, double bundle_range) {
  if (!(bundle_range > 0.0) || !(range >= bundle_range)) return 0;
  int level = 1;
  for (double edge = 2.0 * bundle_range; level < kMaxBundleLevel && range >= edge; edge *= 2.0) {
    ++level;
  }
  return level;
}

void freeExtents(const PointCloud& points_world, const Eigen::Vector3d& origin, double max_range,
                 std::span<const RayStop> stops, const CapsuleShape& shape,
                 const VoxelGrid* bundle_grid, double bundle_range, FreeBundleBuffers& buffers,
                 std::vector<FreeExtent>& out) {
  out.clear();
  const bool bundle = bundle_grid != nullptr;
  const std::size_t n = points_world.size();
  // Each ray's hit number (the stop it takes: rays with a length that are not cut, in order).
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
  // Rays by the cube of their hit (a cut ray, or one outside the addressable range, alone: the
  // key `alone`), rays in order within each, lone rays last; the cubes ranked in the window of
  // the max range around the origin.
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& rays = buffers.rays;
  std::uint64_t alone = std::uint64_t{1} << 48;
  if (bundle) {
    alone = sortByVoxel(
        n,
        [&](std::size_t i) {
          if (takes[i] == 0) return std::optional<VoxelKey>();
          std::optional<VoxelKey> key = bundle_grid->pointToKey(points_world[i]);
          const int level =
              bundleLevel((points_world[i].cast<double>() - origin).norm(), bundle_range);
          if (key && level > 0) {
            // The coarser cube's first key: keys are offset by 2^15, so clearing low bits
            // aligns cubes of 2^level keys on the grid's origin.
            const auto mask = static_cast<std::uint16_t>(~((1U << level) - 1U));
            key = VoxelKey{static_cast<std::uint16_t>(key->x & mask),
                           static_cast<std::uint16_t>(key->y & mask),
                           static_cast<std::uint16_t>(key->z & mask)};
          }
          return key;
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

}  // namespace densemap::kernel
