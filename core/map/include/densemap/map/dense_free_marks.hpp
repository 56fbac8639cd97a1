#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "densemap/map/block_layout.hpp"
#include "densemap/map/scan_update.hpp"

namespace densemap {

/// The free marks of one scan under UpdateRule::kSet, in a dense array of 8^3 blocks over a
/// box of block coordinates: marking a voxel is an index computation and a bit set, with no
/// hash probe and no branch on block changes (a ray changes block every few voxels, which the
/// ScanUpdate's last-block cache mispredicts). Voxels outside the box go to a ScanUpdate given
/// by the caller, so any box is correct; a box around every ray is fast.
/// Single-writer, like ScanUpdate; the array is kept between scans and only touched blocks are
/// cleared.
class DenseFreeMarks {
 public:
  /// Starts a scan over the blocks of voxels [min, max]. Returns false (and covers nothing)
  /// when that is more than `max_blocks` blocks.
  bool reset(const VoxelKey& min, const VoxelKey& max, std::size_t max_blocks);

  /// The box's first block and block count along axis a (0 when reset failed).
  [[nodiscard]] unsigned blockMin(int a) const { return min_[a]; }
  [[nodiscard]] unsigned blockCount(int a) const { return n_[a]; }

  /// markFree unless `region` holds `k`; returns whether it marked. `region` must share this
  /// box's block indexing (CullingRegion::sharesFrame): one index serves both lookups.
  template <class Region>
  bool markFreeUnlessIn(const Region& region, const VoxelKey& k, ScanUpdate& outside) {
    const std::uint32_t i = blockIndex(k);
    if (i == kOutside) {
      if (region.contains(k)) return false;
      outside.markFree(k);
      return true;
    }
    const int index = block::indexOf(k);
    if (region.culledAt(i, index)) return false;
    setAt(i, index);
    return true;
  }

  /// Marks `k` free when inside the box; otherwise into `outside`.
  void markFree(const VoxelKey& k, ScanUpdate& outside) {
    const std::uint32_t i = blockIndex(k);
    if (i == kOutside) {
      outside.markFree(k);
      return;
    }
    setAt(i, block::indexOf(k));
  }

  /// ORs the marks into `update` (as free marks) and clears them.
  void flushInto(ScanUpdate& update);

  /// Calls f(block key, mask) for each block marked so far (the marks stay).
  template <class F>
  void forEachMarked(F&& f) const {
    for (std::size_t t = 0; t < touched_count_; ++t) {
      const std::uint32_t i = touched_[t];
      f(blockKeyAt(i), masks_[i]);
    }
  }

  /// Marks one ray's voxels as markFree does, with the hot state (the arrays' pointers, the
  /// box, the touched count, the ray's last block) in locals until finish(): markFree's members
  /// are reloaded and stored around every mark (a mask word's store may alias a size_t
  /// member), and its first-touch bookkeeping runs at every voxel, here once per block the ray
  /// enters. For the forward walks (markRay); the culled backward walk was 9% slower with it.
  /// Not to outlive the scan's reset; one Marker at a time.
  class Marker {
   public:
    Marker(DenseFreeMarks& marks, ScanUpdate& outside)
        : marks_(marks),
          outside_(outside),
          masks_(marks.masks_.data()),
          seen_(marks.seen_.data()),
          touched_(marks.touched_.data()),
          count_(marks.touched_count_),
          min_{marks.min_[0], marks.min_[1], marks.min_[2]},
          n_{marks.n_[0], marks.n_[1], marks.n_[2]} {}
    /// Writes the touched count back (the marks are in place already).
    void finish() { marks_.touched_count_ = count_; }

    void markFree(const VoxelKey& k) {
      const std::uint32_t i = blockIndexIn(k, min_, n_);
      if (i == kOutside) {
        outside_.markFree(k);
        return;
      }
      if (i != last_) {  // a block the ray enters: first touch of the scan?
        touched_[count_] = i;
        count_ += seen_[i] ^ 1U;
        seen_[i] = 1;
        last_ = i;
      }
      block::setBit(masks_[i], block::indexOf(k));
    }

   private:
    DenseFreeMarks& marks_;
    ScanUpdate& outside_;
    block::BlockMask* masks_;
    std::uint8_t* seen_;
    std::uint32_t* touched_;
    std::size_t count_;
    unsigned min_[3], n_[3];
    std::uint32_t last_ = kOutside;
  };

 private:
  static constexpr std::uint32_t kOutside = ~std::uint32_t{0};
  /// The index of `k`'s block in a box of first block `min` and block counts `n`, or kOutside.
  [[nodiscard]] static std::uint32_t blockIndexIn(const VoxelKey& k, const unsigned (&min)[3],
                                                  const unsigned (&n)[3]) {
    const unsigned bx = static_cast<unsigned>(k.x >> block::kShift) - min[0];
    const unsigned by = static_cast<unsigned>(k.y >> block::kShift) - min[1];
    const unsigned bz = static_cast<unsigned>(k.z >> block::kShift) - min[2];
    if (bx >= n[0] || by >= n[1] || bz >= n[2]) return kOutside;
    return (bz * n[1] + by) * n[0] + bx;
  }
  /// The block key (block::blockOf) of block `i` of the box.
  [[nodiscard]] std::uint64_t blockKeyAt(std::uint32_t i) const;
  /// The index of `k`'s block in the box, or kOutside.
  [[nodiscard]] std::uint32_t blockIndex(const VoxelKey& k) const {
    return blockIndexIn(k, min_, n_);
  }
  /// Sets voxel `index` of block `i`, with branch-free first-touch bookkeeping: the touched
  /// slot is overwritten until the count moves.
  void setAt(std::uint32_t i, int index) {
    touched_[touched_count_] = i;
    touched_count_ += seen_[i] ^ 1U;
    seen_[i] = 1;
    block::setBit(masks_[i], index);
  }

  unsigned min_[3] = {0, 0, 0};
  unsigned n_[3] = {0, 0, 0};
  std::vector<block::BlockMask> masks_;
  std::vector<std::uint8_t> seen_;
  std::vector<std::uint32_t> touched_;  // one spare slot for the branch-free append
  std::size_t touched_count_ = 0;
};

}  // namespace densemap
