#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/map/block_layout.hpp"

namespace densemap::kernel {

/// A ray's free extent: free evidence for the voxels its traversal visits.
struct FreeExtent {
  Point3f from, to;
};

/// kAkimapRays' fast free evidence (issue 29): instead of one capsule kernel per 0.3 m piece of
/// every ray (millions per 64-beam scan, each scheduled, sorted and evaluated over its bounding
/// box), each ray's free extent is walked once with the voxel traversal the log-odds map uses
/// (Amanatides & Woo), and every voxel it visits gets sf2 * k(d / length), k the sparse kernel
/// (Eq. 3.5) of d, the voxel centre's distance from the extent: the value the segment kernels
/// give on the ray's own voxels. Voxels the traversal does not visit get none (at 0.2 m
/// cells and a 0.15 m kernel those would weigh under 3% of sf2).
///
/// Sums are fixed point (2^-30) in per-thread block buffers kept between scans: integer sums do
/// not depend on the order of the rays, so the map does not depend on the thread count. Not
/// thread-safe itself (one scan at a time); accumulate() runs its rays in parallel.
class FreeTraversal {
 public:
  struct Block {
    std::uint64_t key = 0;
    std::array<std::int64_t, block::kVoxels> sum{};
    block::BlockMask mask{};
  };
  static constexpr double kScale = 1073741824.0;  // 2^30 per unit of evidence

  FreeTraversal();
  ~FreeTraversal();
  FreeTraversal(const FreeTraversal&) = delete;
  FreeTraversal& operator=(const FreeTraversal&) = delete;

  /// Walks every extent; returns the voxel visits. The result (blocks()) replaces the last scan's.
  std::size_t accumulate(const VoxelGrid& grid, std::span<const FreeExtent> extents, double sf2,
                         double length_m);
  /// The blocks reached by the last accumulate(), in ascending key order, sums merged.
  [[nodiscard]] const std::vector<Block>& blocks() const { return merged_; }

 private:
  struct Buffers;
  std::unique_ptr<Buffers> buffers_;
  std::vector<Block> merged_;
};

}  // namespace densemap::kernel
