#include "densemap/map/dense_marks.hpp"

namespace densemap {

bool DenseMarks::reset(const VoxelKey& min, const VoxelKey& max, std::size_t max_blocks) {
  discard();  // marks a scan left unflushed (it threw) are not the next scan's
  std::size_t blocks = 1;
  for (int a = 0; a < 3; ++a) {
    const unsigned lo = static_cast<unsigned>(min[a] >> block::kShift);
    const unsigned hi = static_cast<unsigned>(max[a] >> block::kShift);
    min_[a] = lo;
    n_[a] = hi >= lo ? hi - lo + 1 : 0;
    blocks *= n_[a];
  }
  if (blocks > max_blocks) {
    n_[0] = n_[1] = n_[2] = 0;
    return false;
  }
  if (masks_.size() < blocks) {
    if (!masks_.assign(blocks) || !occupied_.assign(blocks) || !seen_.assign(blocks) ||
        !touched_.assign(blocks + 1)) {
      masks_.assign(0);
      n_[0] = n_[1] = n_[2] = 0;
      return false;
    }
  }
  return true;
}

void DenseMarks::discard() {
  for (std::size_t t = 0; t < touched_count_; ++t) {
    const std::uint32_t i = touched_[t];
    masks_[i] = {};
    occupied_[i] = {};
    seen_[i] = 0;
  }
  touched_count_ = 0;
  queue_.clear();
  back_queue_.clear();
}

std::uint64_t DenseMarks::blockKeyAt(std::uint32_t i) const {
  const std::uint32_t bx = i % n_[0];
  const std::uint32_t by = (i / n_[0]) % n_[1];
  const std::uint32_t bz = i / (n_[0] * n_[1]);
  const VoxelKey first{static_cast<std::uint16_t>((bx + min_[0]) << block::kShift),
                       static_cast<std::uint16_t>((by + min_[1]) << block::kShift),
                       static_cast<std::uint16_t>((bz + min_[2]) << block::kShift)};
  return block::blockOf(first);
}

bool DenseMarks::absorb(DenseMarks& other) {
  for (int a = 0; a < 3; ++a) {
    if (other.min_[a] != min_[a] || other.n_[a] != n_[a]) return false;
  }
  for (std::size_t t = 0; t < other.touched_count_; ++t) {
    const std::uint32_t i = other.touched_[t];
    touch(i);
    for (int w = 0; w < block::kMaskWords; ++w) {
      masks_[i][w] |= other.masks_[i][w];
      occupied_[i][w] |= other.occupied_[i][w];
    }
  }
  other.discard();
  return true;
}

void DenseMarks::flushInto(ScanUpdate& update) {
  for (std::size_t t = 0; t < touched_count_; ++t) {
    const std::uint32_t i = touched_[t];
    // A StepMarker enters blocks before marking: a walk may stop in one without a mark.
    const bool free = block::anyBit(masks_[i]), occupied = block::anyBit(occupied_[i]);
    if (free || occupied) update.orMarks(blockKeyAt(i), masks_[i], occupied_[i]);
  }
  discard();
}

}  // namespace densemap
