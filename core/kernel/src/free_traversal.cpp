#include "free_traversal.hpp"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <deque>

#include "densemap/kernel/kernel_function.hpp"

namespace densemap::kernel {
namespace {

/// One thread's blocks of one scan: a slot per block (a deque: slots never move, and are kept
/// between scans), a hash from block key to slot, and in front of it a small direct-mapped
/// cache (a capsule's slices and rows alternate between a few neighbouring blocks).
struct ThreadBlocks {
  static constexpr int kCacheSize = 16;
  std::deque<FreeTraversal::Block> slots;
  std::size_t used = 0;
  std::unordered_map<std::uint64_t, FreeTraversal::Block*> index;
  std::array<std::uint64_t, kCacheSize> cache_keys{};
  std::array<FreeTraversal::Block*, kCacheSize> cache_blocks{};

  ThreadBlocks() { cache_keys.fill(~std::uint64_t{0}); }
  void reset() {
    used = 0;
    index.clear();
    cache_keys.fill(~std::uint64_t{0});
    last_key = ~std::uint64_t{0};
  }
  std::uint64_t last_key = ~std::uint64_t{0};
  FreeTraversal::Block* last = nullptr;

  FreeTraversal::Block& blockFor(std::uint64_t key) {
    if (key == last_key) return *last;
    last_key = key;
    last = &lookup(key);
    return *last;
  }
  FreeTraversal::Block& lookup(std::uint64_t key) {
    const std::size_t line = (key ^ (key >> 13) ^ (key >> 26)) & (kCacheSize - 1);
    if (cache_keys[line] == key) return *cache_blocks[line];
    auto [it, fresh] = index.try_emplace(key, nullptr);
    if (fresh) {
      if (used == slots.size()) slots.emplace_back();
      FreeTraversal::Block& b = slots[used++];
      b.key = key;
      b.sum.fill(0);
      b.mask.fill(0);
      it->second = &b;
    }
    cache_keys[line] = key;
    cache_blocks[line] = it->second;
    return *it->second;
  }
};

/// Calls visit(key, d2) once for every voxel whose centre lies within `radius` of the segment
/// [a, b] (d2: that squared distance), slice by slice along the segment's dominant axis: per
/// slice, the rows of the other two axes that the capsule reaches, per row the interval of the
/// third axis inside the infinite cylinder around the segment's line (a superset of the
/// capsule), each candidate then checked with its exact distance. Keys are clamped to the
/// addressable range (a clamped candidate lies farther than `radius` and is not visited).
template <class Visit>
void forEachVoxelNear(const VoxelGrid& grid, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                      double radius, Visit&& visit) {
  const Eigen::Vector3d seg = b - a;
  const double len2 = seg.squaredNorm();
  if (!(len2 > 0.0)) return;
  const double inverse_len2 = 1.0 / len2;
  const Eigen::Vector3d u = seg / std::sqrt(len2);
  int ax = 0;
  seg.cwiseAbs().maxCoeff(&ax);
  const int bx = (ax + 1) % 3, cx = (ax + 2) % 3;
  const double r2 = radius * radius;
  const double res = grid.resolution();
  // Key of a coordinate, clamped into the addressable range ([0, 65535] as ints).
  const double inverse_res = 1.0 / res;  // a multiplication: the division was 22% of a scan
  const auto keyOf = [&](double v) {     // clamped first, then truncation is floor (k >= 0)
    const double k = std::clamp(v * inverse_res + 32768.0, 0.0, 65535.0);
    return static_cast<int>(k);
  };
  const double inverse_seg_ax = 1.0 / seg[ax];
  const int i0 = keyOf(std::min(a[ax], b[ax]) - radius),
            i1 = keyOf(std::max(a[ax], b[ax]) + radius);
  for (int i = i0; i <= i1; ++i) {
    const double x = grid.keyToCoord(static_cast<std::uint16_t>(i));
    // The part of the segment within `radius` of this slice along ax bounds its rows.
    double t0 = (x - radius - a[ax]) * inverse_seg_ax, t1 = (x + radius - a[ax]) * inverse_seg_ax;
    if (t0 > t1) std::swap(t0, t1);
    // Every voxel of an interior slice has its nearest point of the line on the segment (the
    // foot lies within `radius` of the slice along ax): the line's distance is the capsule's.
    const bool interior = t0 > 0.0 && t1 < 1.0;
    t0 = std::max(t0, 0.0);
    t1 = std::min(t1, 1.0);
    if (t0 > t1) continue;
    const double yb0 = a[bx] + t0 * seg[bx], yb1 = a[bx] + t1 * seg[bx];
    const int j0 = keyOf(std::min(yb0, yb1) - radius), j1 = keyOf(std::max(yb0, yb1) + radius);
    const double wa = x - a[ax];
    const double qa = 1.0 - u[cx] * u[cx];
    const double inverse_qa = 1.0 / qa;
    for (int j = j0; j <= j1; ++j) {
      const double y = grid.keyToCoord(static_cast<std::uint16_t>(j));
      // The squared distance from the line is qa w_c^2 + 2 qb w_c + q0, w = q - a.
      const double wb = y - a[bx];
      const double p = wa * u[ax] + wb * u[bx];
      const double qb = -u[cx] * p;
      const double q0 = wa * wa + wb * wb - p * p;
      const double disc = qb * qb - qa * (q0 - r2);
      if (disc < 0.0) continue;
      const double root = std::sqrt(disc);
      const double slack = 1e-9;
      const int k0 = keyOf(a[cx] + (-qb - root) * inverse_qa - slack);
      const int k1 = keyOf(a[cx] + (-qb + root) * inverse_qa + slack);
      for (int k = k0; k <= k1; ++k) {
        const double z = grid.keyToCoord(static_cast<std::uint16_t>(k));
        double d2 = 0.0;
        if (interior) {
          const double wc = z - a[cx];
          d2 = std::max(0.0, (qa * wc + 2.0 * qb) * wc + q0);
        } else {
          Eigen::Vector3d c;
          c[ax] = x;
          c[bx] = y;
          c[cx] = z;
          const Eigen::Vector3d w = c - a;
          const double t = std::clamp(w.dot(seg) * inverse_len2, 0.0, 1.0);
          d2 = (w - t * seg).squaredNorm();
        }
        if (!(d2 < r2)) continue;
        int key[3];
        key[ax] = i;
        key[bx] = j;
        key[cx] = k;
        visit(VoxelKey{static_cast<std::uint16_t>(key[0]), static_cast<std::uint16_t>(key[1]),
                       static_cast<std::uint16_t>(key[2])},
              d2);
      }
    }
  }
}

}  // namespace

struct FreeTraversal::Buffers {
  tbb::enumerable_thread_specific<ThreadBlocks> threads;
};

FreeTraversal::FreeTraversal() : buffers_(std::make_unique<Buffers>()) {}
FreeTraversal::~FreeTraversal() = default;

std::size_t FreeTraversal::accumulate(const VoxelGrid& grid, std::span<const FreeExtent> extents) {
  for (ThreadBlocks& t : buffers_->threads) t.reset();
  const SquaredKernelTable& table = squaredKernel();
  std::atomic<std::size_t> visits{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, extents.size(), 512),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      ThreadBlocks& mine = buffers_->threads.local();
                      std::size_t n = 0;
                      for (std::size_t r = range.begin(); r != range.end(); ++r) {
                        const FreeExtent& e = extents[r];
                        const double inverse_length2 = 1.0 / (e.radius_m * e.radius_m);
                        const double scaled_weight = e.weight * kScale;
                        forEachVoxelNear(grid, e.from, e.to, e.radius_m,
                                         [&](const VoxelKey& key, double d2) {
                                           ++n;
                                           const double w = table(d2 * inverse_length2);
                                           if (!(w > 0.0)) return;
                                           Block& blk = mine.blockFor(block::blockOf(key));
                                           const int cell = block::indexOf(key);
                                           // w >= 0: rounding half up without llround's call.
                                           blk.sum[static_cast<std::size_t>(cell)] +=
                                               static_cast<std::int64_t>(w * scaled_weight + 0.5);
                                           block::setBit(blk.mask, cell);
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
      for (int c = 0; c < block::kVoxels; ++c)
        m.sum[static_cast<std::size_t>(c)] += all[i]->sum[static_cast<std::size_t>(c)];
      for (int w = 0; w < block::kMaskWords; ++w)
        m.mask[static_cast<std::size_t>(w)] |= all[i]->mask[static_cast<std::size_t>(w)];
    }
  }
  return visits.load();
}

}  // namespace densemap::kernel
