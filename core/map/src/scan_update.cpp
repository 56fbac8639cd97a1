#include "densemap/map/scan_update.hpp"

#include <algorithm>

namespace densemap {

void ScanUpdate::merge(const ScanUpdate& other) {
  for (const auto& [block_key, b] : other.blocks_) {
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
  if ((blocks_.size() + 1) * 2 > slot_keys_.size()) {
    grow(blocks_.size() + 1);  // indexes every block, appended ones too
  } else if (indexed_ < blocks_.size()) {
    const std::size_t mask = slot_keys_.size() - 1;  // appended blocks not yet in the slots
    for (std::size_t i = indexed_; i < blocks_.size(); ++i) {
      std::size_t slot = slotOf(blocks_[i].first, mask);
      while (slot_keys_[slot] != kEmpty) slot = (slot + 1) & mask;
      slot_keys_[slot] = blocks_[i].first;
      slot_blocks_[slot] = static_cast<std::uint32_t>(i);
    }
  }
  indexed_ = blocks_.size();
  const std::size_t mask = slot_keys_.size() - 1;
  for (std::size_t slot = slotOf(block_key, mask);; slot = (slot + 1) & mask) {
    if (slot_keys_[slot] == block_key) return slot_blocks_[slot];
    if (slot_keys_[slot] == kEmpty) {
      slot_keys_[slot] = block_key;
      slot_blocks_[slot] = static_cast<std::uint32_t>(blocks_.size());
      Block& b = blocks_.emplace_back(block_key, Block{}).second;
      indexed_ = blocks_.size();
      if (rule_ == UpdateRule::kPerRay) b.counts = std::make_unique<Counts>();
      return slot_blocks_[slot];
    }
  }
}

std::size_t ScanUpdate::appendBlocks(std::size_t n) {
  cached_key_ = kEmpty;
  const std::size_t first = blocks_.size();
  blocks_.resize(first + n);
  return first;
}

void ScanUpdate::truncateBlocks(std::size_t n) {
  if (n >= blocks_.size()) return;
  blocks_.resize(n);
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
  for (std::uint32_t i = 0; i < blocks_.size(); ++i) {
    std::size_t slot = slotOf(blocks_[i].first, mask);
    while (slot_keys_[slot] != kEmpty) slot = (slot + 1) & mask;
    slot_keys_[slot] = blocks_[i].first;
    slot_blocks_[slot] = i;
  }
}

void ScanUpdate::clear() {
  blocks_.clear();
  if (indexed_ > 0) std::fill(slot_keys_.begin(), slot_keys_.end(), kEmpty);
  indexed_ = 0;
  cached_key_ = kEmpty;
}

std::size_t ScanUpdate::freeCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks_) {
    for (int w = 0; w < block::kMaskWords; ++w) n += std::popcount(b.free[w] & ~b.occupied[w]);
  }
  return n;
}

std::size_t ScanUpdate::occupiedCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks_) {
    n += block::countBits(b.occupied);
  }
  return n;
}

}  // namespace densemap
