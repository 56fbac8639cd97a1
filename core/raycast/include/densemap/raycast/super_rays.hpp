#pragma once

#include <tbb/enumerable_thread_specific.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "densemap/raycast/ray_marking.hpp"

namespace densemap {

/// What grouping one scan's rays into super rays did (the dissertation's Table 2.2 figures).
struct SuperRayStats {
  std::size_t super_rays = 0;  // rays out standing for more than one ray
};

/// Groups the rays of one scan that end in the same voxel and cross exactly the same voxels
/// into one super ray weighted by their number (dissertation Sec. 2.3.1-2.3.4).
///
/// Per end voxel E with at least `min_points` rays (fewer pass through, Sec. 2.4.3), in
/// parallel: for each of the three axis pairs (the mapping lines of Alg. 2: XY, YZ, ZX), the
/// grid points between the sensor's voxel and E whose projection falls inside the cell's
/// frustum are the "critical slopes" D_b(m) / D_a(n) — D_a(n) being the distance along axis a
/// from the sensor to the n-th voxel border the traversal crosses. A ray's segment on a mapping
/// line is the rank of its slope |d_b| / |d_a| among them; rays with the same step signs and the
/// same segment on all three lines cross borders in the same order (Theorem 2), hence visit the
/// same voxels.
///
/// Exactness against OctoMap's float traversal (traverseRay): slopes are taken from each ray's
/// float direction exactly as the traversal computes it, against the traversal's own borders
/// (with its float half step); a ray whose slope lies within a relative 1e-9 of a critical slope
/// (the traversal's double arithmetic could order those crossings either way), or whose end lies
/// within 1e-5 x length + 1e-6 x resolution of E's faces (where the traversal's `dist > length`
/// stop or key comparison could differ), is passed through on its own. A super ray is then the
/// first of its rays, so traversing it visits exactly what each of its rays would.
///
/// Thread-safety: one build() at a time per builder; runs in the caller's task arena.
class SuperRayBuilder {
 public:
  /// Replaces `rays` (as made by rayEndFor, weight 1 each) by super rays and pass-through rays.
  SuperRayStats build(const VoxelGrid& grid, const Point3f& origin, std::vector<RayEnd>& rays,
                      std::size_t min_points);

 private:
  struct Scratch {
    struct Info {
      float dir[3];
      std::uint32_t segment[3];
      std::uint32_t step_class;
      bool certain;
    };
    std::vector<Info> info;
    std::vector<double> slopes;
    std::vector<std::uint32_t> order;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed;  // (packed group, ray)
    std::vector<RayEnd> cell;
  };

  /// Groups the rays of one end voxel (all with the same key and occupied flag) into `out`
  /// (room for rays.size()); returns how many were written.
  static std::size_t groupCell(const VoxelGrid& grid, const Point3f& origin,
                               std::span<const RayEnd> rays, RayEnd* out, Scratch& scratch);
  // groupCell's stages, in order (super_rays.cpp says what each does).
  static void describeRays(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& end_key,
                           std::span<const RayEnd> rays, Scratch& scratch);
  static void classifySlopes(const VoxelGrid& grid, const Point3f& origin,
                             const VoxelKey& origin_key, const VoxelKey& end_key, Scratch& scratch);
  static std::size_t emitGroups(std::span<const RayEnd> rays, RayEnd* out, Scratch& scratch);

  std::vector<std::uint64_t> order_;  // (cell code, ray index), sorted
  std::vector<std::uint64_t> sort_tmp_;
  std::vector<std::uint32_t> radix_count_;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> runs_;  // the end voxels grouped
  std::vector<std::uint8_t> grouped_;                          // per ray: in one of runs_
  std::vector<std::uint32_t> written_;
  std::vector<RayEnd> out_;
  tbb::enumerable_thread_specific<Scratch> scratch_;
};

}  // namespace densemap
