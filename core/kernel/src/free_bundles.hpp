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
  std::vector<Eigen::Vector3d> ends;  // freeExtentsTree: each level-0 bundle's sum of free ends
  std::vector<double> counts;         // ... and its count of rays with free extents
  std::vector<std::uint32_t> level_starts;  // ... each level's bundles (level-0 bundle index)
  std::vector<std::pair<std::uint64_t, std::uint32_t>> rays, rays_other;
  std::vector<std::uint32_t> radix_counts;
  std::vector<std::size_t> group_starts;
};

/// `bundle_grid`: the cubes whose hits' rays are bundled (null: no bundles).
void freeExtents(const PointCloud& points_world, const Eigen::Vector3d& origin, double max_range,
                 std::span<const RayStop> stops, const CapsuleShape& shape,
                 const VoxelGrid* bundle_grid, FreeBundleBuffers& buffers,
                 std::vector<FreeExtent>& out);

/// The most levels of freeExtentsTree.
inline constexpr int kMaxTreeLevels = 12;
/// kAkimapRays' free extents as a tree of bundles (`levels` >= 1): the rays are bundled by the
/// cube of `bundle_grid` their hit lies in (level 0), those cubes by the aligned cubes of 2^3
/// of them (level 1), and so on up to `levels`. A bundle of level b (edge c_b = 2^b c_0) is one
/// capsule over the part of its rays from 2^-(b+1) to 2^-b of the way from the origin to the
/// mean of their free ends (level 0: from half way to the end; the top level: from the
/// origin), weighing the count of its rays: there its rays lie within c_b 2^-b = c_0 of each
/// other, as a level-0 bundle's do at its end, so a ray's evidence moves sideways no more than
/// a level-0 bundle moves it, and near the origin, where every ray of a scan runs close to the
/// others, a few capsules stand for thousands. A bundle whose rays are those of a single child
/// gives no capsule of its own: the child's starts where the parent's would (a lone ray is
/// still one capsule, bit for bit). Joints between levels are open ends (FreeExtent). A cut
/// ray is a level-0 bundle of its own, bundled from level 1 by its cut point; a ray outside
/// the addressable range is never bundled. Tips stay one per ray. Slots: a slot per ray (its
/// tip), per level-0 bundle, then per bundle of each higher level in order, with holes (no
/// length, weight 0) where none is given.
void freeExtentsTree(const PointCloud& points_world, const Eigen::Vector3d& origin,
                     double max_range, std::span<const RayStop> stops, const CapsuleShape& shape,
                     const VoxelGrid& bundle_grid, int levels, FreeBundleBuffers& buffers,
                     std::vector<FreeExtent>& out);

}  // namespace densemap::kernel
