#include "densemap/traversal/scan_update.hpp"

#include <algorithm>

namespace densemap {

void ScanUpdate::merge(const ScanUpdate& other) {
  for (const auto& [block_key, b] : other.blocks()) {
    Block& mine = blockFor(block_key);
    for (int w = 0; w < block::kMaskWords; ++w) {
      mine.free[w] |= b.free[w];
      mine.occupied[w] |= b.occupied[w];
    }
    if (mine.counts && b.counts) {
      for (int i = 0; i < block::kVoxels; ++i) {
        mine.counts->free[i] += b.counts->free[i];
        mine.counts->occupied[i] += b.counts->occupied[i];
      }
    }
  }
}

namespace {

std::size_t slotOf(std::uint64_t key, std::size_t mask) {
  return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> 32) & mask;
}

}  // namespace

std::uint32_t ScanUpdate::indexFor(std::uint64_t block_key) {
  if ((count_ + 1) * 2 > slot_keys_.size()) {
    grow(count_ + 1);  // indexes every block, appended ones too
  } else if (indexed_ < count_) {
    const std::size_t mask = slot_keys_.size() - 1;  // appended blocks not yet in the slots
    for (std::size_t i = indexed_; i < count_; ++i) {
      std::size_t slot = slotOf(room_[i].first, mask);
      while (slot_keys_[slot] != kEmpty) slot = (slot + 1) & mask;
      slot_keys_[slot] = room_[i].first;
      slot_blocks_[slot] = static_cast<std::uint32_t>(i);
    }
  }
  indexed_ = count_;
  const std::size_t mask = slot_keys_.size() - 1;
  for (std::size_t slot = slotOf(block_key, mask);; slot = (slot + 1) & mask) {
    if (slot_keys_[slot] == block_key) return slot_blocks_[slot];
    if (slot_keys_[slot] == kEmpty) {
      slot_keys_[slot] = block_key;
      slot_blocks_[slot] = static_cast<std::uint32_t>(count_);
      if (count_ == room_.size()) room_.emplace_back();
      auto& [key, b] = room_[count_++];
      key = block_key;
      b.free = {};
      b.occupied = {};
      if (rule_ == UpdateRule::kPerRay) b.counts = std::make_unique<Counts>();
      indexed_ = count_;
      return slot_blocks_[slot];
    }
  }
}

std::size_t ScanUpdate::appendBlocks(std::size_t n) {
  cached_key_ = kEmpty;
  const std::size_t first = count_;
  if (room_.size() < first + n) room_.resize(first + n);
  count_ = first + n;
  return first;
}

void ScanUpdate::truncateBlocks(std::size_t n) {
  if (n >= count_) return;
  dropCounts(n);
  count_ = n;
  cached_key_ = kEmpty;
  if (indexed_ > n) {
    grow(n);  // the slots indexed blocks that are gone: the rest indexed again
    indexed_ = n;
  }
}

void ScanUpdate::grow(std::size_t blocks) {
  std::size_t size = std::max<std::size_t>(1024, slot_keys_.size() * 2);
  while (size < blocks * 2) size *= 2;
  slot_keys_.assign(size, kEmpty);
  slot_blocks_.assign(size, 0);
  const std::size_t mask = size - 1;
  for (std::uint32_t i = 0; i < count_; ++i) {
    std::size_t slot = slotOf(room_[i].first, mask);
    while (slot_keys_[slot] != kEmpty) slot = (slot + 1) & mask;
    slot_keys_[slot] = room_[i].first;
    slot_blocks_[slot] = i;
  }
}

void ScanUpdate::dropCounts(std::size_t from) {
  if (rule_ != UpdateRule::kPerRay) return;  // kSet blocks have none
  for (std::size_t i = from; i < count_; ++i) room_[i].second.counts.reset();
}

void ScanUpdate::clear() {
  dropCounts(0);
  count_ = 0;
  if (indexed_ > 0) std::fill(slot_keys_.begin(), slot_keys_.end(), kEmpty);
  indexed_ = 0;
  cached_key_ = kEmpty;
}

std::size_t ScanUpdate::freeCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks()) {
    for (int w = 0; w < block::kMaskWords; ++w) n += std::popcount(b.free[w] & ~b.occupied[w]);
  }
  return n;
}

std::size_t ScanUpdate::occupiedCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks()) {
    n += block::countBits(b.occupied);
  }
  return n;
}

}  // namespace densemap
