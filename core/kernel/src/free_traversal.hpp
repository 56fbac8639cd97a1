#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/geometry/voxel_grid.hpp"

namespace densemap::kernel {

/// A ray's free extent: free evidence for the voxels within the kernel's reach of it.
struct FreeExtent {
  Eigen::Vector3d from, to;
  double radius_m = 0.1;  // the kernel's support radius (length scale)
  double weight = 1.0;    // its value on the extent (sf2)
  /// An open end has no cap: a voxel whose nearest point of the axis' line lies beyond it gets
  /// nothing (a joint with the next piece of the same rays, which covers that side).
  bool open_from = false, open_to = false;
};

/// kAkimapRays' fast free evidence: instead of one capsule kernel per 0.3 m piece of
/// every ray (millions per 64-beam scan, each scheduled, sorted and evaluated over its bounding
/// box), each ray's free extent (and its tip) is one capsule, rasterised slice by slice (every
/// voxel whose centre lies within `radius_m` of the extent is visited once per ray, no sort;
/// a short capsule, such as a tip, is its box tested whole), and each such voxel gets weight *
/// k(d / radius_m), k the sparse kernel (Eq. 3.5) of d, its centre's distance from the extent.
///
/// Sums are fixed point in per-thread block buffers (released by release()): integer sums do not
/// depend on the order of the rays, so the map does not depend on the thread count. They are
/// 32-bit (half the bytes and cache lines of 64-bit sums), so each scan takes the finest step
/// 2^-k (k <= 30) at which no voxel's sum can exceed 2^31 - 1: a voxel gets at most every
/// extent's weight once, so the step follows from the scan's total weight (scale()). Not
/// thread-safe itself (one scan at a time); accumulate() runs its rays in parallel.
class FreeTraversal {
 public:
  struct Block {
    std::uint64_t key = 0;
    std::array<std::int32_t, block::kVoxels> sum{};
    block::BlockMask mask{};
  };
  static constexpr double kMaxScale = 1073741824.0;  // 2^30 per unit of evidence at most
  /// The fixed-point scale for extents whose weights (after the reach's compensation) sum to
  /// `total_weight`: the largest power of two <= kMaxScale with every sum within int32.
  [[nodiscard]] static double scaleFor(double total_weight);

  FreeTraversal();
  ~FreeTraversal();
  FreeTraversal(const FreeTraversal&) = delete;
  FreeTraversal& operator=(const FreeTraversal&) = delete;

  /// Rasterises every extent (one of no length is skipped: freeExtents' holes); returns the
  /// (extent, voxel) pairs that got evidence. The result
  /// (blocks()) replaces the last scan's. `reach` (0, 1]: only voxels within reach * radius_m
  /// of an extent are visited, and the weights are scaled by 1 / evidenceShare(reach), so a
  /// ray leaves the same evidence per metre: the kernel's outer part holds little of it (0.85:
  /// 0.02% in 28% of the voxels).
  std::size_t accumulate(const VoxelGrid& grid, std::span<const FreeExtent> extents,
                         double reach = 1.0);
  /// The share of a capsule's free evidence (per metre of ray, the kernel integrated over the
  /// disc across it) within `reach` of its axis (a fraction of its radius): 1 at reach >= 1.
  [[nodiscard]] static double evidenceShare(double reach);
  /// Bytes its buffers hold.
  [[nodiscard]] std::size_t memoryBytes() const;
  /// Gives the buffers' memory back once blocks() is done with (for the next scan's other
  /// stages; they are made again by the next accumulate()).
  void release();
  /// The blocks reached by the last accumulate(), in ascending key order, sums merged (valid
  /// until the next accumulate()).
  [[nodiscard]] const std::vector<const Block*>& blocks() const { return merged_; }
  /// Units of a sum per unit of evidence in the last accumulate()'s blocks (scaleFor).
  [[nodiscard]] double scale() const { return scale_; }
  /// A block's sums as free evidence: beta[cell] += float(sum[cell] * inverse_scale) and the
  /// cell known, for each cell of its mask. Sixteen cells at a time in AVX-512 lanes where the
  /// processor has them and `lanes` is set, bit for bit as a cell at a time.
  static void addEvidence(const Block& block, double inverse_scale,
                          std::array<float, block::kVoxels>& beta, block::BlockMask& known,
                          bool lanes = true);

 private:
  struct Buffers;
  std::unique_ptr<Buffers> buffers_;
  std::vector<const Block*> merged_;
  double scale_ = kMaxScale;
};

}  // namespace densemap::kernel
