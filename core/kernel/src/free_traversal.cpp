#include "free_traversal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <atomic>
#include <numeric>

#include "densemap/geometry/ray_traversal.hpp"
#include "densemap/kernel/kernel_function.hpp"

namespace densemap::kernel {
namespace {

/// The sparse kernel as a table of r^2 (no sqrt, sin or cos per visit), linear between entries:
/// within 2e-5 of sparseKernel.
class KernelTable {
 public:
  static constexpr int kEntries = 4096;
  KernelTable() {
    for (int i = 0; i <= kEntries; ++i) {
      values_[static_cast<std::size_t>(i)] = sparseKernel(std::sqrt(double(i) / kEntries));
    }
  }
  [[nodiscard]] double operator()(double r2) const {
    if (!(r2 < 1.0)) return 0.0;
    const double x = r2 * kEntries;
    const int i = static_cast<int>(x);
    const double f = x - i;
    return values_[static_cast<std::size_t>(i)] * (1.0 - f) +
           values_[static_cast<std::size_t>(i) + 1] * f;
  }

 private:
  std::array<double, kEntries + 1> values_{};
};

const KernelTable& kernelTable() {
  static const KernelTable table;
  return table;
}

/// One thread's blocks of one scan: a slot per block (kept between scans), a hash from block key
/// to slot and a last-block cache (a ray stays in one block for several voxels).
struct ThreadBlocks {
  std::vector<FreeTraversal::Block> slots;
  std::size_t used = 0;
  std::unordered_map<std::uint64_t, std::uint32_t> index;
  std::uint64_t last_key = ~std::uint64_t{0};
  FreeTraversal::Block* last = nullptr;

  void reset() {
    used = 0;
    index.clear();
    last_key = ~std::uint64_t{0};
    last = nullptr;
  }
  FreeTraversal::Block& blockFor(std::uint64_t key) {
    if (key == last_key) return *last;
    auto [it, fresh] = index.try_emplace(key, static_cast<std::uint32_t>(used));
    if (fresh) {
      if (used == slots.size()) slots.emplace_back();
      FreeTraversal::Block& b = slots[used++];
      b.key = key;
      b.sum.fill(0);
      b.mask.fill(0);
    }
    last_key = key;
    last = &slots[it->second];
    return *last;
  }
};

}  // namespace

struct FreeTraversal::Buffers {
  tbb::enumerable_thread_specific<ThreadBlocks> threads;
};

FreeTraversal::FreeTraversal() : buffers_(std::make_unique<Buffers>()) {}
FreeTraversal::~FreeTraversal() = default;

std::size_t FreeTraversal::accumulate(const VoxelGrid& grid, std::span<const FreeExtent> extents,
                                      double sf2, double length_m) {
  for (ThreadBlocks& t : buffers_->threads) t.reset();
  const KernelTable& table = kernelTable();
  const double inverse_length2 = 1.0 / (length_m * length_m);
  const double scaled_sf2 = sf2 * kScale;
  std::atomic<std::size_t> visits{0};
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, extents.size(), 512),
      [&](const tbb::blocked_range<std::size_t>& range) {
        ThreadBlocks& mine = buffers_->threads.local();
        std::size_t n = 0;
        for (std::size_t r = range.begin(); r != range.end(); ++r) {
          const Eigen::Vector3d a = extents[r].from.cast<double>();
          const Eigen::Vector3d seg = extents[r].to.cast<double>() - a;
          const double len2 = seg.squaredNorm();
          const double inverse_len2 = len2 > 0.0 ? 1.0 / len2 : 0.0;
          traverseRay(grid, extents[r].from, extents[r].to, [&](const VoxelKey& key) {
            ++n;
            const Eigen::Vector3d c(grid.keyToCoord(key.x), grid.keyToCoord(key.y),
                                    grid.keyToCoord(key.z));
            const Eigen::Vector3d ac = c - a;
            const double t = std::clamp(ac.dot(seg) * inverse_len2, 0.0, 1.0);
            const double d2 = (ac - t * seg).squaredNorm();
            const double w = table(d2 * inverse_length2);
            if (!(w > 0.0)) return;
            Block& b = mine.blockFor(block::blockOf(key));
            const int cell = block::indexOf(key);
            b.sum[static_cast<std::size_t>(cell)] += std::llround(w * scaled_sf2);
            block::setBit(b.mask, cell);
          });
        }
        visits += n;
      });
  // Merge: every thread's blocks by key (ascending), integer sums (exact in any order).
  std::vector<const Block*> all;
  for (const ThreadBlocks& t : buffers_->threads) {
    for (std::size_t s = 0; s < t.used; ++s) all.push_back(&t.slots[s]);
  }
  std::sort(all.begin(), all.end(), [](const Block* x, const Block* y) { return x->key < y->key; });
  std::size_t distinct = 0;
  for (std::size_t i = 0; i < all.size(); ++i) distinct += i == 0 || all[i]->key != all[i - 1]->key;
  merged_.resize(distinct);
  std::size_t out = 0;
  for (std::size_t i = 0; i < all.size();) {
    Block& m = merged_[out++];
    m = *all[i];
    for (++i; i < all.size() && all[i]->key == m.key; ++i) {
      for (int c = 0; c < block::kVoxels; ++c) m.sum[static_cast<std::size_t>(c)] += all[i]->sum[static_cast<std::size_t>(c)];
      for (int w = 0; w < block::kMaskWords; ++w) m.mask[static_cast<std::size_t>(w)] |= all[i]->mask[static_cast<std::size_t>(w)];
    }
  }
  return visits.load();
}

}  // namespace densemap::kernel
