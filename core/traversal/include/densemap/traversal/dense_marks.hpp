#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "densemap/geometry/chunk_runner.hpp"

#include "densemap/geometry/block_layout.hpp"
#include "densemap/traversal/scan_update.hpp"

namespace densemap {

struct TraversalLanes;

/// The marks of one scan under UpdateRule::kSet, free and occupied, in dense arrays of 8^3
/// blocks over a box of block coordinates: marking a voxel is an index computation and a bit
/// set, with no hash probe and no branch on block changes (a ray changes block every few
/// voxels, which the ScanUpdate's last-block cache mispredicts; consecutive rays end in
/// different blocks, a probe each). Voxels outside the box go to a ScanUpdate given by the
/// caller, so any box is correct; a box around every ray is fast.
/// Single-writer, like ScanUpdate; the array is kept between scans and only touched blocks are
/// cleared.
class DenseMarks {
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

  /// Marks `k` occupied when inside the box; otherwise into `outside`.
  void markOccupied(const VoxelKey& k, ScanUpdate& outside) {
    const std::uint32_t i = blockIndex(k);
    if (i == kOutside) {
      outside.markOccupied(k);
      return;
    }
    touch(i);
    block::setBit(occupied_[i], block::indexOf(k));
  }
  /// markOccupied for keys[l], the lanes l of `lanes` (up to 8), the first-touch bookkeeping
  /// in locals; returns the lanes whose key is outside the box (the caller's to mark).
  unsigned markOccupiedLanes(const VoxelKey* keys, unsigned lanes) {
    std::uint8_t* const seen = seen_.data();
    std::uint32_t* const touched = touched_.data();
    std::size_t count = touched_count_;
    unsigned outside = 0;
    for (unsigned m = lanes; m != 0; m &= m - 1) {
      const int l = std::countr_zero(m);
      const std::uint32_t i = blockIndexIn(keys[l], min_, n_);
      if (i == kOutside) {
        outside |= 1U << l;
        continue;
      }
      touchIn(i, seen, touched, count);
      block::setBit(occupied_[i], block::indexOf(keys[l]));
    }
    touched_count_ = count;
    return outside;
  }

  /// ORs the marks into `update` and clears them.
  void flushInto(ScanUpdate& update);
  /// The marks of these and of `others` (other workers') ORed into `update` — which must hold
  /// none of this box's blocks (a fresh one) — and cleared in all: the marks of flushing each,
  /// the box's blocks in block order (x fastest, then y, then z), then those of others over
  /// another box.
  /// Others over the same blocks are ORed in by block index, not by hash probe, the blocks split
  /// into chunks that `runner` may run at once; others over another box are flushed one by one.
  void flushAllInto(std::span<DenseMarks* const> others, ScanUpdate& update,
                    const ChunkRunner& runner);

  /// Calls f(block key, free mask) for each block with free marks so far (the marks stay).
  template <class F>
  void forEachMarkedFree(F&& f) const {
    const auto each = [&](std::uint32_t i) {
      if (block::anyBit(masks_[i])) f(blockKeyAt(i), masks_[i]);
    };
    if (unlisted_) {
      forEachSeen(each);  // the list lacks blocks only seen (see finishPended)
      return;
    }
    for (std::size_t t = 0; t < touched_count_; ++t) each(touched_[t]);
  }

  /// The first-touch bookkeeping, branch free: block `i` appended at touched[count] (the slot is
  /// overwritten until the count moves) and counted once, the first time seen[i] is set. The one
  /// definition, for the members (touch) and for loops that keep the three in locals or
  /// registers (Cursor, the queued walks' finish: seen's byte stores may alias any member).
  template <class Count>  // std::size_t, or 32 bits where a uint64_t store must not alias it
  static void touchIn(std::uint32_t i, std::uint8_t* seen, std::uint32_t* touched, Count& count) {
    touched[count] = i;
    count += seen[i] ^ 1U;
    seen[i] = 1;
  }

  /// A walk's voxel in the box as a value (walk_marker.hpp).
  class Cursor;

  /// Marks one ray's voxels following its walk step by step (walk_marker.hpp).
  class StepMarker;

  /// A queued walk's voxel: its bit address in the box's mask array (block * 512 +
  /// block::indexOf), and per axis the steps left to the next block border, a step's change of
  /// the address inside a block and into the next one (as DenseMarks::Cursor follows it).
  struct WalkPlace {
    std::uint64_t addr;
    std::int32_t left[3];
    std::int32_t small[3];
    std::int32_t wrap[3];
  };
  /// A forward walk queued by queueWalk: countedSteps' times from its first voxel.
  struct QueuedWalk {
    double t_max[3];
    double t_delta[3];
    double t_last;  // the last crossing's time (endOf's TraversalEndTimes): no step's is later
    WalkPlace at;
    std::int32_t steps;  // after the first voxel
  };
  /// A backward walk queued by queueBackWalk: traverseRayBackward's fast loop (BackwardWalk's
  /// heads, crossings left, deltas and bound) from the end voxel.
  struct QueuedBackWalk {
    double head[3];
    double t_delta[3];
    double bound;
    WalkPlace at;
    std::int32_t next[3];
    std::int32_t total;  // the forward traversal's voxels: the most steps back
    std::uint32_t id;    // the caller's
  };
  /// How markQueued and markQueuedBack walk: kBest as kFixedSixteen where the processor has
  /// AVX-512 (hasWideWalks), as kFixedEight where it has AVX2 (hasFourWalks), else one at a
  /// time as kScalar does (countedSteps, backwardSteps); kFour 4 at a time in AVX2 lanes of
  /// doubles;
  /// kFixedEight 8 at a time in AVX2 lanes of 32-bit fixed-point times, each decision checked
  /// to win by more than the rounding's bound, a walk with a decision that does not handed over
  /// to kFour from its start (fixedHandedOver counts them); kFixedSixteen kFixedEight's walks
  /// sixteen at a time in AVX-512 lanes where the processor has it (hasWideWalks; else as
  /// kFixedEight). Without AVX2, all as kScalar.
  enum class WalkKernel { kBest, kFour, kFixedEight, kScalar, kFixedSixteen };
  [[nodiscard]] static bool hasWideWalks();
  [[nodiscard]] static bool hasFourWalks();

  /// Queues traverseRay's counted walk (countedTotal(start) = `total` > 0 voxels: the first,
  /// then countedSteps' total - 1 steps from `t_max`, `t_delta`) from voxel `first`, moving by
  /// `delta[a]` along axis a, to the voxel before `last`: marks the first voxel now and the
  /// others in markQueued. False (nothing marked or queued) unless `first` and `last` are both
  /// in the box (so are the walk's voxels between them).
  /// `t_last`: the time of its last crossing (endOf's TraversalEndTimes, the largest of `last`).
  bool queueWalk(const VoxelKey& first, const int (&delta)[3], const VoxelKey& last,
                 const double (&t_max)[3], const double (&t_delta)[3], int total, double t_last) {
    // Forward walks start in the sensor's voxel: their places come from placeFrom's memo.
    const WalkPlace* from = placeFrom(first, delta);
    if (from == nullptr || blockIndex(last) == kOutside) return false;
    const WalkPlace at = *from;
    // Every member assigned (emplace_back() would zero the record first: a `rep stos` that was
    // half of this function's time).
    queue_.push_back(QueuedWalk{{t_max[0], t_max[1], t_max[2]},
                                {t_delta[0], t_delta[1], t_delta[2]},
                                t_last,
                                at,
                                total - 1});
    const auto b = static_cast<std::uint32_t>(at.addr >> 9);
    setAt(b, static_cast<int>(at.addr & (block::kVoxels - 1)));
    return true;
  }
  /// Queues traverseRayBackward's fast walk (prepareBackward's kFast: `head`, `next`, `t_delta`,
  /// `bound`, `total` as in BackwardWalk) from the end voxel `first` (not marked), moving by
  /// `delta[a]` along axis a, to the origin's voxel `last`: markQueuedBack walks it. False
  /// (nothing queued) unless both are in the box.
  bool queueBackWalk(const VoxelKey& first, const int (&delta)[3], const VoxelKey& last,
                     const double (&head)[3], const double (&t_delta)[3], const int (&next)[3],
                     double bound, std::size_t total, std::uint32_t id) {
    WalkPlace at;
    if (!place(first, delta, last, at)) return false;
    back_queue_.push_back(QueuedBackWalk{{head[0], head[1], head[2]},
                                         {t_delta[0], t_delta[1], t_delta[2]},
                                         bound,
                                         at,
                                         {next[0], next[1], next[2]},
                                         static_cast<std::int32_t>(total),
                                         id});
    // (Built whole: see queueWalk.)
    touch(static_cast<std::uint32_t>(at.addr >> 9));  // entered (as cursorFor)
    return true;
  }
  /// Whether queueFixedLanes and markFixedQueued walk the forward walks with `kernel`: kFixedEight,
  /// kFixedSixteen or kBest, where the processor has AVX2.
  [[nodiscard]] static bool queuesFixed(WalkKernel kernel);
  /// Whether `kernel`'s fixed-point forward walks go sixteen at a time (kFixedSixteen, where the
  /// processor has AVX-512).
  [[nodiscard]] static bool walksSixteen(WalkKernel kernel);
  /// queueWalk straight into kFixedEight's terms (queuesFixed) for a caller that can walk any
  /// of them again by its id: the counted walks of rays 0..n-1 of `lanes` (startTraversalLanes'
  /// from voxel `first`; ray l's id ids[l]), each marked from its first voxel, which is marked
  /// now. Returns the lanes queued: counted walks (kClean, countedTotal > 0) with both ends in
  /// the box and times in the fixed point's range (toFixed's); the caller walks the others.
  /// `kernel` (one that queuesFixed): an empty queue takes walksSixteen(kernel)'s layout, field
  /// by field for kFixedSixteen (no transposition before its walk), else a FixedWalk a walk.
  unsigned queueFixedLanes(const TraversalLanes& lanes, int n, const VoxelKey& first,
                           const std::uint32_t* ids, WalkKernel kernel = WalkKernel::kBest);
  /// Walks the walks queueFixedLanes queued (with the kernel they were queued for), then
  /// empties that queue. The ids of those it hands over (a decision too close to call in fixed
  /// point) are appended to `handed_over`: the caller walks them exactly (what they marked is
  /// part of their marks).
  void markFixedQueued(std::vector<std::uint32_t>& handed_over);
  /// Voxels markQueuedBack marked and skipped (markRayCulled's counts).
  struct BackWalkCounts {
    std::size_t visits = 0;
    std::size_t culled = 0;
  };
  /// Walks the queued backward walks, then empties the queue: each step moves (the latest
  /// crossing undone) and stops at a voxel `culled` holds (a culling region's bits in this box's
  /// block layout, block b's at [b]: CullingRegion::frameMasks), else marks it. A walk whose
  /// decision does not win by its bound is the caller's to walk exactly: its id is appended to
  /// `handed_over` and its counts are not added (what it marked is part of what the exact walk
  /// marks). A walk's counts are visits = voxels marked, culled = total - visits.
  BackWalkCounts markQueuedBack(const block::BlockMask* culled,
                                std::vector<std::uint32_t>& handed_over,
                                WalkKernel kernel = WalkKernel::kBest);
  /// Marks the queued walks' voxels after their first, then empties the queue.
  void markQueued(WalkKernel kernel = WalkKernel::kBest);
  /// The walks (forward and backward) kFixedEight handed over to kFour since construction
  /// (decisions too close to call in fixed point; not those out of its range).
  [[nodiscard]] std::size_t fixedHandedOver() const { return fixed_handed_; }

  /// A forward walk in kFixedEight's terms: per axis the crossing time and its step in units of
  /// 2^-k of the walk's last crossing time (2^28 to 2^29 units, clamped at 2^30), the slack a
  /// decision must win by, the steps, and the place mirrored as the AVX2 walks keep it.
  struct FixedWalk {
    std::int32_t t[3];
    std::int32_t d[3];
    std::int32_t slack;
    std::int32_t steps;
    std::int32_t addr;  // mirrored: addr ^ flip is the voxel's address
    std::int32_t flip;
    std::int32_t cross[3];  // per axis: the block crossing's increment, less the axis' unit
    std::uint32_t index;    // in the queue (queueFixedLanes': the caller's id)
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
  /// After the queued walks: their pended marks (`n_pend` of pend_w_ / pend_b_) ORed in, the
  /// blocks they entered (`n_entered` of entered_) through the first-touch bookkeeping.
  void finishQueued(std::size_t n_pend, std::size_t n_entered);
  /// The same for walks that list no blocks entered (walkFour): every block a forward walk
  /// marks holds one of its pended words, so the pended words' blocks are the blocks entered.
  /// Their seen flags are set, not the list (a store a pend, where the list took five
  /// instructions more): the list is `unlisted_` until relist() or the flush rebuilds it.
  void finishPended(std::size_t n_pend);
  /// finishPended for the 32-bit words kFixedEight pends (pend32_w_ / pend32_b_).
  void finishPended32(std::size_t n_pend);
  /// markQueued's kFixedEight (kFixedSixteen): the queue in fixed point, walked; the walks it
  /// hands over, and those out of its range, walked by kFour.
  void markQueuedFixed(WalkKernel kernel);
  /// fixed_cols_ with room for twice the walks queued (those kept).
  void growFixedColumns();
  /// markQueuedBack's kFixedEight (kFixedSixteen; the queue not emptied): the walks in fixed
  /// point, walked against `culled`; those it hands over, and those out of its range, walked by
  /// kFour (whose own hand-overs go to `handed_over`).
  BackWalkCounts markQueuedBackFixed(const block::BlockMask* culled,
                                     std::vector<std::uint32_t>& handed_over, WalkKernel kernel);
  /// Calls f(i) for each block i in [from, to) whose seen flag is set, in index order.
  template <class F>
  void forEachSeenIn(std::size_t from, std::size_t to, F&& f) const {
    const std::uint8_t* const seen = seen_.data();
    std::size_t i = from;
    for (; i + 8 <= to; i += 8) {  // eight flags (0 or 1) at a time: most words are all clear
      std::uint64_t flags;
      std::memcpy(&flags, seen + i, sizeof flags);
      for (; flags != 0; flags &= flags - 1) {
        f(static_cast<std::uint32_t>(i + (static_cast<unsigned>(std::countr_zero(flags)) >> 3)));
      }
    }
    for (; i < to; ++i) {
      if (seen[i] != 0) f(static_cast<std::uint32_t>(i));
    }
  }
  /// forEachSeenIn over the whole box.
  template <class F>
  void forEachSeen(F&& f) const {
    forEachSeenIn(0, boxBlocks(), f);
  }
  [[nodiscard]] std::size_t boxBlocks() const {
    return static_cast<std::size_t>(n_[0]) * n_[1] * n_[2];
  }
  /// The list of touched blocks rebuilt from the seen flags when it is unlisted_ (serially).
  void relist();
  /// place's walk place from voxel `first` moving by `delta` (each -1, 0 or 1), or null when
  /// `first` is outside the box: memoized for the last `first` (the 27 deltas' places), since
  /// a scan's forward walks all start in the sensor's voxel.
  const WalkPlace* placeFrom(const VoxelKey& first, const int (&delta)[3]) {
    if (!memo_valid_ || !(first == memo_first_)) {
      memo_first_ = first;
      memo_valid_ = true;
      memo_filled_ = 0;
      memo_fixed_filled_ = 0;
      memo_inside_ = blockIndex(first) != kOutside;
    }
    if (!memo_inside_) return nullptr;
    const int slot = (delta[0] + 1) + 3 * (delta[1] + 1) + 9 * (delta[2] + 1);
    if ((memo_filled_ >> slot & 1U) == 0) {
      (void)place(first, delta, first, memo_places_[slot]);
      memo_filled_ |= 1U << slot;
    }
    return &memo_places_[slot];
  }
  /// A walk's place from voxel `first` toward `last` (moving by `delta`), when both are in the
  /// box (else false).
  bool place(const VoxelKey& first, const int (&delta)[3], const VoxelKey& last, WalkPlace& at) {
    const std::uint32_t b = blockIndex(first);
    if (b == kOutside || blockIndex(last) == kOutside) return false;
    at.addr = static_cast<std::uint64_t>(b) * block::kVoxels +
              static_cast<unsigned>(block::indexOf(first));
    const int in_block[3] = {first.x & (block::kEdge - 1), first.y & (block::kEdge - 1),
                             first.z & (block::kEdge - 1)};
    const std::int32_t stride[3] = {1, static_cast<std::int32_t>(n_[0]),
                                    static_cast<std::int32_t>(n_[0] * n_[1])};
    // (Unrolled: a backward walk's place is computed per walk; the loop took ~150 instructions.)
#pragma GCC unroll 3
    for (int a = 0; a < 3; ++a) {
      at.left[a] = delta[a] > 0 ? block::kEdge - in_block[a] : in_block[a] + 1;
      at.small[a] = delta[a] * (1 << (block::kShift * a));
      at.wrap[a] = delta[a] * stride[a] * block::kVoxels - (block::kEdge - 1) * at.small[a];
    }
    return true;
  }
  /// Sets voxel `index` of block `i`, with branch-free first-touch bookkeeping: the touched
  /// slot is overwritten until the count moves.
  void setAt(std::uint32_t i, int index) {
    touch(i);
    block::setBit(masks_[i], index);
  }
  void touch(std::uint32_t i) { touchIn(i, seen_.data(), touched_.data(), touched_count_); }

  unsigned min_[3] = {0, 0, 0};
  unsigned n_[3] = {0, 0, 0};
  // placeFrom's memo (invalid after reset: the box's indexing may change).
  VoxelKey memo_first_{};
  bool memo_valid_ = false;
  bool memo_inside_ = false;
  std::uint32_t memo_filled_ = 0;  // the slots computed
  WalkPlace memo_places_[27]{};
  // queueFixedLanes': the memo's places in FixedWalk's terms (addr, flip, cross), the slots
  // computed, and the address of the first voxel it marked since the queue was last walked.
  static constexpr std::uint64_t kNoVoxel = ~std::uint64_t{0};
  std::uint32_t memo_fixed_filled_ = 0;
  FixedWalk memo_fixed_[27]{};
  std::uint64_t fixed_first_ = kNoVoxel;
  /// Clears the marks made since the last flush (none when every scan was flushed).
  void discard();
  /// Block i's marks and first-touch flag cleared; the list of touched blocks and the queues
  /// emptied (their blocks' marks are the caller's to clear).
  void clearBlock(std::uint32_t i);
  /// Puts the touched blocks' list in block index order (its blocks' seen flags set: each
  /// once), by a sort or by reading the box's seen flags in chunks with `runner`.
  void orderTouched(const ChunkRunner& runner);
  void forgetList();

  /// An array of zeroed Ts from calloc: the pages a scan never touches stay unmapped (the
  /// largest box, 2^21 blocks, is 128 MiB of masks per array), where a vector writes them all.
  template <class T>
  class ZeroedArray {
   public:
    /// Replaces the contents by n zeroed elements; false when out of memory (then empty).
    bool assign(std::size_t n) {
      data_.reset(static_cast<T*>(std::calloc(n, sizeof(T))));
      size_ = data_ != nullptr ? n : 0;
      return data_ != nullptr;
    }
    [[nodiscard]] std::size_t size() const { return size_; }
    [[nodiscard]] T* data() { return data_.get(); }
    [[nodiscard]] const T* data() const { return data_.get(); }
    T& operator[](std::size_t i) { return data_[i]; }
    const T& operator[](std::size_t i) const { return data_[i]; }

   private:
    struct Free {
      void operator()(T* p) const { std::free(p); }
    };
    std::unique_ptr<T[], Free> data_;
    std::size_t size_ = 0;
  };

  ZeroedArray<block::BlockMask> masks_;     // free marks
  ZeroedArray<block::BlockMask> occupied_;  // occupied marks
  ZeroedArray<std::uint8_t> seen_;
  ZeroedArray<std::uint32_t> touched_;  // one spare slot for the branch-free append
  std::size_t touched_count_ = 0;
  bool unlisted_ = false;  // blocks seen (seen_) that touched_ does not list: finishPended's
  std::vector<QueuedWalk> queue_;
  std::vector<QueuedBackWalk> back_queue_;
  std::vector<std::uint32_t> entered_;              // markQueued's: blocks the walks entered
  std::vector<std::uint64_t> pend_w_, pend_b_;      // markQueued's: marks gathered per word
  std::vector<std::uint32_t> pend32_w_, pend32_b_;  // kFixedEight's: per 32-bit word
  std::vector<std::int32_t> sixteen_rows_;          // kFixedSixteen's walks, field by field
  std::vector<FixedWalk> fixed_;                    // kFixedEight's queue
  std::vector<FixedWalk> fixed_queue_;              // queueFixedLanes' (n_fixed_ of them)
  // queueFixedLanes' for kFixedSixteen (fixed_columns_): 14 rows of fixed_cols_cap_ + 16.
  std::vector<std::int32_t> fixed_cols_;
  std::size_t fixed_cols_cap_ = 0;
  bool fixed_columns_ = false;
  std::size_t n_fixed_ = 0, fixed_steps_ = 0;  // (fixed_steps_: their totals)
  std::vector<QueuedWalk> handed_;             // kFixedEight's hand-overs
  std::vector<QueuedBackWalk> back_handed_;    // (backward)
  std::vector<std::uint32_t> handed_ids_;
  std::size_t fixed_handed_ = 0;
  std::vector<std::size_t> chunk_held_;  // flushAllInto's: blocks with marks per chunk
};

}  // namespace densemap

#include "densemap/traversal/walk_marker.hpp"
