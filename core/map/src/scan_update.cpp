#include "densemap/map/scan_update.hpp"

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

void ScanUpdate::clear() {
  blocks_.clear();
  cached_ = nullptr;
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
    for (int w = 0; w < block::kMaskWords; ++w) n += std::popcount(b.occupied[w]);
  }
  return n;
}

}  // namespace densemap
