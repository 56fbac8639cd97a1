#pragma once

#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "free_traversal.hpp"

namespace densemap::kernel {

/// The capsules' radii and weights (kAkimapRays: the free extent's and the tip's).
struct CapsuleShape {
  double free_radius_m = 0.15, free_weight = 1.0;
  double tip_radius_m = 0.1, tip_weight = 1.0;
};

/// kAkimapRays' free extents: each ray's free extent [origin, hit - stop.free] and
/// tip [.., hit - stop.tip] (as makeRaySegments with one piece per ray; a ray cut at
/// `max_range` is free to there, without a tip). With `bundle`, the rays whose hits share a
/// voxel give one free capsule from the origin to the mean of their free ends, weighing their
/// count: such rays run within a voxel of each other all the way, and a dense 64-beam scan has
/// several per voxel (BALM at 0.2 m: about 3), each costing a whole capsule. Tips stay one per
/// ray: they lie near the surface, where the rays of a voxel spread the most against it
/// (bundling them costs BALM's hold-out MSE). Cubes as small as the capsule's radius would be
/// faster at 0.1 m but cost the oracle scenes' MSE, hence `free_bundle_m` (0.2 m by default).
/// A voxel hit by one ray gives that ray's own
/// capsule, bit for bit; cut rays are never bundled. The extents come in a fixed order (by
/// voxel: its rays' tips in ray order, then its capsule) whatever the thread count, with a
/// hole (no length, weight 0) for each ray without a tip and each voxel whose rays have no
/// free extent: a slot per ray and per voxel, written in one pass.
/// freeExtents' per-scan arrays (the caller releases them once the extents are made).
struct FreeBundleBuffers {
  std::vector<std::uint32_t> hit_of, takes;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> rays, rays_other;
  std::vector<std::uint32_t> radix_counts;
  std::vector<std::size_t> group_starts;
};

/// `bundle_grid`: the cubes whose hits' rays are bundled (null: no bundles). `bundle_range`
/// (> 0): a hit at least this far from the origin is bundled by the cube of 2^b of them that
/// holds it (aligned on the grid's keys), b = 1 + floor(log2(range / bundle_range)), at most
/// kMaxBundleLevel.
inline constexpr int kMaxBundleLevel = 3;
void freeExtents(const PointCloud& points_world, const Eigen::Vector3d& origin, double max_range,
                 std::span<const RayStop> stops, const CapsuleShape& shape,
                 const VoxelGrid* bundle_grid, double bundle_range, FreeBundleBuffers& buffers,
                 std::vector<FreeExtent>& out);
/// The bundle level (0 .. kMaxBundleLevel) of a hit `range` from the origin.
[[nodiscard]] int bundleLevel(double range, double bundle_range);

}  // namespace densemap::kernel
