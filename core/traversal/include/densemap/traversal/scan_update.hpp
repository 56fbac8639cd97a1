#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/traversal/update_rule.hpp"

namespace densemap {

/// The candidate cells of one scan, per 8^3 block: bit masks of the cells crossed (free) and
/// ended in (occupied), and under UpdateRule::kPerRay also how many rays did each. Merging is
/// a bitwise OR plus integer sums, so the result is independent of the order in which rays (or
/// threads) marked it.
/// Single-writer: each thread fills its own ScanUpdate, then they are merged.
class ScanUpdate {
 public:
  struct Counts {
    std::array<std::uint32_t, block::kVoxels> free{};
    std::array<std::uint32_t, block::kVoxels> occupied{};
  };
  struct Block {
    block::BlockMask free{};
    block::BlockMask occupied{};
    std::unique_ptr<Counts> counts;  // kPerRay only
  };

  explicit ScanUpdate(UpdateRule rule = UpdateRule::kSet) : rule_(rule) {}
  // A moved-from update is empty (its count goes with its room).
  ScanUpdate(ScanUpdate&& other) noexcept { *this = std::move(other); }
  ScanUpdate& operator=(ScanUpdate&& other) noexcept {
    rule_ = other.rule_;
    room_ = std::move(other.room_);
    count_ = std::exchange(other.count_, 0);
    slot_keys_ = std::move(other.slot_keys_);
    slot_blocks_ = std::move(other.slot_blocks_);
    indexed_ = std::exchange(other.indexed_, 0);
    cached_key_ = std::exchange(other.cached_key_, kEmpty);
    cached_index_ = other.cached_index_;
    return *this;
  }

  [[nodiscard]] UpdateRule rule() const { return rule_; }
  /// Empties the update and sets the rule for the next scan.
  void reset(UpdateRule rule) {
    clear();
    rule_ = rule;
  }

  /// `weight` rays crossed / ended in the cell (the weight only counts under kPerRay).
  void markFree(const VoxelKey& k, std::uint32_t weight = 1) {
    Block& b = blockFor(block::blockOf(k));
    const int i = block::indexOf(k);
    block::setBit(b.free, i);
    if (b.counts) b.counts->free[i] += weight;
  }
  void markOccupied(const VoxelKey& k, std::uint32_t weight = 1) {
    Block& b = blockFor(block::blockOf(k));
    const int i = block::indexOf(k);
    block::setBit(b.occupied, i);
    if (b.counts) b.counts->occupied[i] += weight;
  }

  /// ORs a block's worth of free and occupied marks in (UpdateRule::kSet only: no counts).
  void orMarks(std::uint64_t block_key, const block::BlockMask& free,
               const block::BlockMask& occupied) {
    Block& b = blockFor(block_key);
    for (int w = 0; w < block::kMaskWords; ++w) {
      b.free[w] |= free[w];
      b.occupied[w] |= occupied[w];
    }
  }

  /// Appends `n` blocks (kSet) that a caller fills — in parallel if it likes: key and marks,
  /// every one of them (the room may hold an earlier scan's blocks: nothing is cleared here, so
  /// appending costs no serial pass over the room), the keys distinct and none already in the
  /// update — before the update is used again (the key index takes them in at the next mark or
  /// merge, if one comes). Returns the position of the first new block.
  std::size_t appendBlocks(std::size_t n);
  [[nodiscard]] std::pair<std::uint64_t, Block>& blockAt(std::size_t j) { return room_[j]; }
  /// Drops the blocks from position `n` on (appended room a caller did not fill).
  void truncateBlocks(std::size_t n);

  /// Adds another update (same rule) into this one.
  void merge(const ScanUpdate& other);
  void clear();

  [[nodiscard]] bool empty() const { return count_ == 0; }
  /// (block key, cells) in the order blocks were first marked.
  [[nodiscard]] std::span<const std::pair<std::uint64_t, Block>> blocks() const {
    return {room_.data(), count_};
  }
  /// Cells to be updated as free (crossed, not ended in) and as occupied.
  [[nodiscard]] std::size_t freeCount() const;
  [[nodiscard]] std::size_t occupiedCount() const;

  /// Calls f(key, CellHits) once per cell of the update. Under kSet a cell ended in is occupied
  /// only (occupied wins); under kPerRay both counts are given.
  template <class F>
  void forEachCell(F&& f) const {
    for (const auto& [block_key, b] : blocks()) forEachCellInBlock(block_key, b, f);
  }
  template <class F>
  static void forEachCellInBlock(std::uint64_t block_key, const Block& b, F&& f) {
    for (int w = 0; w < block::kMaskWords; ++w) {
      std::uint64_t any = b.free[w] | b.occupied[w];
      while (any != 0) {
        const int bit = std::countr_zero(any);
        any &= any - 1;
        const int index = w * 64 + bit;
        CellHits hits;
        if (b.counts) {
          hits = {b.counts->free[index], b.counts->occupied[index]};
        } else if (((b.occupied[w] >> bit) & 1U) != 0) {
          hits.occupied = 1;
        } else {
          hits.free = 1;
        }
        f(block::keyOf(block_key, index), hits);
      }
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};

  Block& blockFor(std::uint64_t block_key) {
    // Consecutive cells of a ray mostly share a block: remember the last one.
    if (cached_key_ == block_key) return room_[cached_index_].second;
    cached_key_ = block_key;
    cached_index_ = indexFor(block_key);
    return room_[cached_index_].second;
  }
  /// Drops the counts of the blocks from position `from` on (kPerRay): the room keeps none.
  void dropCounts(std::size_t from);
  /// Open addressing with linear probing on the block key; creates the block when missing.
  std::uint32_t indexFor(std::uint64_t block_key);
  /// A slot table for at least `blocks` blocks (twice as many slots, a power of two, at least
  /// double the present), every block indexed again.
  void grow(std::size_t blocks);

  UpdateRule rule_ = UpdateRule::kSet;
  // The update's blocks are room_[0, count_); the rest of the room holds blocks of earlier scans,
  // kept constructed (kSet: no counts) so that neither clearing nor appending walks them.
  std::vector<std::pair<std::uint64_t, Block>> room_;
  std::size_t count_ = 0;
  std::vector<std::uint64_t> slot_keys_;    // kEmpty or a block key; size a power of two
  std::vector<std::uint32_t> slot_blocks_;  // index into room_
  std::size_t indexed_ = 0;                 // room_[0, indexed_) are in the slots
  std::uint64_t cached_key_ = kEmpty;
  std::uint32_t cached_index_ = 0;
};

}  // namespace densemap
