#include "densemap/map/scan_update.hpp"

namespace densemap {

void ScanUpdate::merge(const ScanUpdate& other) {
  for (const auto& [block_key, m] : other.blocks_) {
    Masks& mine = blocks_[block_key];
    for (int w = 0; w < block::kMaskWords; ++w) {
      mine.free[w] |= m.free[w];
      mine.occupied[w] |= m.occupied[w];
    }
  }
  cached_ = nullptr;
}

void ScanUpdate::clear() {
  blocks_.clear();
  cached_ = nullptr;
}

std::size_t ScanUpdate::freeCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, m] : blocks_) {
    for (int w = 0; w < block::kMaskWords; ++w) n += std::popcount(m.free[w] & ~m.occupied[w]);
  }
  return n;
}

std::size_t ScanUpdate::occupiedCount() const {
  std::size_t n = 0;
  for (const auto& [block_key, m] : blocks_) {
    for (int w = 0; w < block::kMaskWords; ++w) n += std::popcount(m.occupied[w]);
  }
  return n;
}

}  // namespace densemap
