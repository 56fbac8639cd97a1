#include "densemap/traversal/dense_marks.hpp"

#include <algorithm>
#include <bit>
#include <cstring>

namespace densemap {

bool DenseMarks::reset(const VoxelKey& min, const VoxelKey& max, std::size_t max_blocks) {
  discard();  // marks a scan left unflushed (it threw) are not the next scan's
  memo_valid_ = false;
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
    // Twice the box, up to the limit: a box a little larger than the last one does not map the
    // arrays again (each time, every page a scan touches is faulted in anew).
    const std::size_t room = std::max(blocks, std::min(max_blocks, 2 * blocks));
    if (!masks_.assign(room) || !occupied_.assign(room) || !seen_.assign(room) ||
        !touched_.assign(room + 1)) {
      masks_.assign(0);
      n_[0] = n_[1] = n_[2] = 0;
      return false;
    }
  }
  return true;
}

void DenseMarks::clearBlock(std::uint32_t i) {
  masks_[i] = {};
  occupied_[i] = {};
  seen_[i] = 0;
}

void DenseMarks::forgetList() {
  touched_count_ = 0;
  unlisted_ = false;
  queue_.clear();
  back_queue_.clear();
  n_fixed_ = 0;
  fixed_steps_ = 0;
  fixed_first_ = kNoVoxel;
}

void DenseMarks::relist() {
  if (!unlisted_) return;
  std::uint32_t* const touched = touched_.data();
  std::size_t count = 0;
  forEachSeen([&](std::uint32_t i) { touched[count++] = i; });
  touched_count_ = count;
  unlisted_ = false;
}

void DenseMarks::discard() {
  relist();
  for (std::size_t t = 0; t < touched_count_; ++t) clearBlock(touched_[t]);
  forgetList();
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

void DenseMarks::orderTouched(const ChunkRunner& runner) {
  const std::size_t n = touched_count_;
  const std::size_t box = boxBlocks();
  // Sorting is serial; the seen flags of the box, read in chunks side by side, list the same
  // blocks in the same order (a byte a block: cheaper than the sort's n log n steps unless the
  // box is far larger than the list).
  if (!unlisted_ && box > 64 * n) {
    std::sort(touched_.data(), touched_.data() + n);
    return;
  }
  unlisted_ = false;                                   // listed below from the seen flags
  constexpr std::size_t kScan = std::size_t{1} << 15;  // blocks a chunk (a multiple of 8)
  const std::size_t chunks = (box + kScan - 1) / kScan;
  const std::uint8_t* const seen = seen_.data();
  chunk_held_.assign(chunks + 1, 0);
  runner.run(chunks, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c != end; ++c) {
      std::size_t count = 0;
      for (std::size_t i = c * kScan, to = std::min(box, (c + 1) * kScan); i < to; ++i) {
        count += seen[i];  // 0 or 1
      }
      chunk_held_[c + 1] = count;
    }
  });
  for (std::size_t c = 0; c < chunks; ++c) chunk_held_[c + 1] += chunk_held_[c];
  touched_count_ = chunk_held_[chunks];
  runner.run(chunks, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c != end; ++c) {
      std::uint32_t* out = touched_.data() + chunk_held_[c];
      forEachSeenIn(c * kScan, std::min(box, (c + 1) * kScan),
                    [&](std::uint32_t i) { *out++ = i; });
    }
  });
}

void DenseMarks::flushAllInto(std::span<DenseMarks* const> others, ScanUpdate& update,
                              const ChunkRunner& runner) {
  // The others' blocks join this one's list (no marks moved yet): each block once, in order.
  std::vector<DenseMarks*> same, apart;
  for (DenseMarks* other : others) {
    bool shared = true;
    for (int a = 0; a < 3; ++a) {
      shared = shared && other->min_[a] == min_[a] && other->n_[a] == n_[a];
    }
    if (!shared) {
      apart.push_back(other);  // flushed after these (by hash probe: its blocks may be ours)
      continue;
    }
    other->relist();
    for (std::size_t t = 0; t < other->touched_count_; ++t) touch(other->touched_[t]);
    same.push_back(other);
  }
  // In the box's block order (x fastest, then y, then z): the map's apply reads neighbouring
  // blocks one after the other, which it does about twice as fast as in the lanes' interleaved
  // order.
  orderTouched(runner);
  // Chunks of the list in one pass: the others' marks ORed in (and cleared there), then the
  // blocks holding marks written out (a walk may enter a block and stop before marking) from
  // the start of their chunk's room, and cleared. Chunks own distinct blocks and rooms, so
  // they may run at once. (Two passes, a count of the blocks holding marks and then the
  // write-out at their exact places, read every block's marks twice.)
  constexpr std::size_t kChunk = 512, kAhead = 8;
  const std::size_t n = touched_count_;
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  chunk_held_.assign(chunks + 1, 0);
  const std::size_t first = update.appendBlocks(n);  // room for every listed block
  runner.run(chunks, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t c = begin; c != end; ++c) {
      std::size_t at = first + c * kChunk;
      const std::size_t to = std::min(n, (c + 1) * kChunk);
      for (std::size_t t = c * kChunk; t < to; ++t) {
        // The blocks are all over the box (cache misses): a few ahead are fetched meanwhile.
        if (t + kAhead < to) {
          const std::uint32_t ahead = touched_[t + kAhead];
          __builtin_prefetch(&masks_[ahead]);
          __builtin_prefetch(&occupied_[ahead]);
          for (const DenseMarks* other : same) {
            __builtin_prefetch(&other->masks_[ahead]);
            __builtin_prefetch(&other->occupied_[ahead]);
          }
        }
        const std::uint32_t i = touched_[t];
        for (DenseMarks* other : same) {
          if (other->seen_[i] == 0) continue;
          for (int w = 0; w < block::kMaskWords; ++w) {
            masks_[i][w] |= other->masks_[i][w];
            occupied_[i][w] |= other->occupied_[i][w];
          }
          other->clearBlock(i);
        }
        if (block::anyBit(masks_[i]) || block::anyBit(occupied_[i])) {
          auto& [key, b] = update.blockAt(at++);
          key = blockKeyAt(i);
          b.free = masks_[i];
          b.occupied = occupied_[i];
        }
        clearBlock(i);
      }
      chunk_held_[c + 1] = at - (first + c * kChunk);
    }
  });
  // A chunk that wrote fewer blocks than it listed left a gap: the later chunks' blocks move
  // down over it, in order.
  std::size_t end = first;
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::size_t from = first + c * kChunk, held = chunk_held_[c + 1];
    if (end != from) {
      for (std::size_t k = 0; k < held; ++k) {
        update.blockAt(end + k) = std::move(update.blockAt(from + k));
      }
    }
    end += held;
  }
  update.truncateBlocks(end);
  forgetList();
  for (DenseMarks* other : same) other->forgetList();  // their blocks are cleared already
  for (DenseMarks* other : apart) other->flushInto(update);
}

void DenseMarks::flushInto(ScanUpdate& update) {
  relist();
  for (std::size_t t = 0; t < touched_count_; ++t) {
    const std::uint32_t i = touched_[t];
    // A StepMarker enters blocks before marking: a walk may stop in one without a mark.
    const bool free = block::anyBit(masks_[i]), occupied = block::anyBit(occupied_[i]);
    if (free || occupied) update.orMarks(blockKeyAt(i), masks_[i], occupied_[i]);
  }
  discard();
}

}  // namespace densemap
