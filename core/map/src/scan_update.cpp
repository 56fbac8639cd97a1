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
  if ((blocks_.size() + 1) * 2 > slot_keys_.size()) grow();
  const std::size_t mask = slot_keys_.size() - 1;
  for (std::size_t slot = slotOf(block_key, mask);; slot = (slot + 1) & mask) {
    if (slot_keys_[slot] == block_key) return slot_blocks_[slot];
    if (slot_keys_[slot] == kEmpty) {
      slot_keys_[slot] = block_key;
      slot_blocks_[slot] = static_cast<std::uint32_t>(blocks_.size());
      Block& b = blocks_.emplace_back(block_key, Block{}).second;
      if (rule_ == UpdateRule::kPerRay) b.counts = std::make_unique<Counts>();
      return slot_blocks_[slot];
    }
  }
}

void ScanUpdate::grow() {
  const std::size_t size = std::max<std::size_t>(1024, slot_keys_.size() * 2);
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
  std::fill(slot_keys_.begin(), slot_keys_.end(), kEmpty);
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
