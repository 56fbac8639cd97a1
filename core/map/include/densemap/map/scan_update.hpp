#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <unordered_map>

#include "densemap/map/block_layout.hpp"

namespace densemap {

/// The candidate cells of one scan under OctoMap's rule (DESIGN.md, exactness contract): a set
/// of free cells and a set of occupied cells; a cell in both is occupied. Stored as bit masks
/// per 8^3 block so that marking is cheap and merging is a bitwise OR, which makes the result
/// independent of the order in which rays (or threads) marked it.
/// Single-writer: each thread fills its own ScanUpdate, then they are merged.
class ScanUpdate {
 public:
  struct Masks {
    std::array<std::uint64_t, block::kMaskWords> free{};
    std::array<std::uint64_t, block::kMaskWords> occupied{};
  };

  void markFree(const VoxelKey& k) { set(masksFor(block::blockOf(k)).free, block::indexOf(k)); }
  void markOccupied(const VoxelKey& k) {
    set(masksFor(block::blockOf(k)).occupied, block::indexOf(k));
  }

  /// Bitwise OR of another update into this one.
  void merge(const ScanUpdate& other);
  void clear();
  void reserveBlocks(std::size_t n) { blocks_.reserve(n); }

  [[nodiscard]] bool empty() const { return blocks_.empty(); }
  [[nodiscard]] const std::unordered_map<std::uint64_t, Masks>& blocks() const { return blocks_; }
  /// Cells to be updated (free and occupied sets disjoint after "occupied wins").
  [[nodiscard]] std::size_t freeCount() const;
  [[nodiscard]] std::size_t occupiedCount() const;

  /// Calls f(key, occupied) once per cell of the update, occupied winning over free.
  template <class F>
  void forEachCell(F&& f) const {
    for (const auto& [block_key, m] : blocks_) forEachCellInBlock(block_key, m, f);
  }
  template <class F>
  static void forEachCellInBlock(std::uint64_t block_key, const Masks& m, F&& f) {
    for (int w = 0; w < block::kMaskWords; ++w) {
      std::uint64_t any = m.free[w] | m.occupied[w];
      while (any != 0) {
        const int bit = std::countr_zero(any);
        any &= any - 1;
        const int index = w * 64 + bit;
        f(block::keyOf(block_key, index), ((m.occupied[w] >> bit) & 1U) != 0);
      }
    }
  }

 private:
  static void set(std::array<std::uint64_t, block::kMaskWords>& words, int index) {
    words[index >> 6] |= std::uint64_t{1} << (index & 63);
  }
  Masks& masksFor(std::uint64_t block_key) {
    // Consecutive cells of a ray mostly share a block: remember the last one.
    if (cached_ != nullptr && cached_key_ == block_key) return *cached_;
    cached_key_ = block_key;
    cached_ = &blocks_[block_key];  // node-based map: the pointer survives rehashing
    return *cached_;
  }

  std::unordered_map<std::uint64_t, Masks> blocks_;
  std::uint64_t cached_key_ = 0;
  Masks* cached_ = nullptr;
};

}  // namespace densemap
