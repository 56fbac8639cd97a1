#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <bit>
#include <cstdint>
#include <limits>
#include <vector>

#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "radix_sort.hpp"

namespace densemap::kernel::detail {

/// The point samples of a scan bucketed in a dense grid of cubes (counting sort, bucket order
/// x fastest): a box search reads one contiguous run of samples per (y, z) row of buckets.
class SampleIndex {
 public:
  /// A point sample as the index holds it: its position and label beside its index, so that a
  /// search reads one contiguous run per row of buckets (not the samples, scattered).
  struct Entry {
    Eigen::Vector3d x;
    std::uint32_t index = 0;
    bool occupied = false;
  };
  /// The index's arrays, owned by the caller.
  struct Storage {
    std::vector<std::uint32_t> starts;            // per bucket, into entries; see the constructor
    std::vector<Entry> entries;                   // the point samples by bucket
    std::vector<std::uint32_t> bucket;            // per sample
    std::vector<std::uint64_t> keys, keys_other;  // (bucket, index), sorted by the radix sort
    std::vector<std::uint32_t> counts;            // the radix sort's per-chunk counts
  };

  /// Buckets of `cell` metres, made coarser when the samples' box would need more than
  /// `max_cells` of them.
  SampleIndex(const std::vector<Sample>& samples, double cell, std::size_t max_cells,
              Storage& storage)
      : starts_(storage.starts), entries_(storage.entries) {
    // entries_ is resized below (empty means no index).
    const Eigen::AlignedBox3d box = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, samples.size(), 16384), Eigen::AlignedBox3d(),
        [&](const tbb::blocked_range<std::size_t>& r, Eigen::AlignedBox3d b) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (!samples[i].segment) b.extend(samples[i].x);
          }
          return b;
        },
        [](Eigen::AlignedBox3d a, const Eigen::AlignedBox3d& b) { return a.extend(b); });
    if (box.isEmpty()) {
      entries_.clear();
      return;
    }
    const Eigen::Vector3d size = box.sizes();
    cell_ = cell;
    while (cellCount(size) > max_cells) cell_ *= 1.5;
    min_ = box.min();
    for (int a = 0; a < 3; ++a) n_[a] = static_cast<std::int64_t>(size[a] / cell_) + 1;
    const auto buckets = static_cast<std::size_t>(n_[0] * n_[1] * n_[2]);
    std::vector<std::uint32_t>& bucket = storage.bucket;
    bucket.resize(samples.size());
    constexpr std::uint32_t kNone = ~std::uint32_t{0};  // a segment: not indexed
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 16384),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          if (samples[i].segment) {
                            bucket[i] = kNone;
                            continue;
                          }
                          const auto c = cellOf(samples[i].x.array());
                          bucket[i] =
                              static_cast<std::uint32_t>((c[2] * n_[1] + c[1]) * n_[0] + c[0]);
                        }
                      });
    // The indexed samples sorted by (bucket, index): a stable radix sort of (bucket, index)
    // pairs in index order (the order does not depend on the thread count).
    std::vector<std::uint64_t>& keys = storage.keys;
    keys.clear();
    for (std::uint32_t i = 0; i < samples.size(); ++i) {
      if (bucket[i] != kNone) keys.push_back((std::uint64_t{bucket[i]} << 32) | i);
    }
    radixSort(
        keys, storage.keys_other, static_cast<int>(std::bit_width(buckets)),
        [](std::uint64_t k) { return k >> 32; }, storage.counts);
    // starts[b]: the entries of buckets below b (b = 0 .. buckets), so bucket b is
    // [starts[b], starts[b + 1]); each written once, in parallel by the sorted entries.
    starts_.resize(buckets + 2);
    entries_.resize(keys.size());
    const auto bucketAt = [&keys](std::size_t i) {
      return static_cast<std::size_t>(keys[i] >> 32);
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size(), 8192),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          const auto index = static_cast<std::uint32_t>(keys[i]);
                          entries_[i] = {samples[index].x, index, samples[index].occupied};
                          const std::size_t from = i == 0 ? 0 : bucketAt(i - 1) + 1;
                          for (std::size_t b = from; b <= bucketAt(i); ++b) {
                            starts_[b] = static_cast<std::uint32_t>(i);
                          }
                        }
                      });
    const std::size_t after = keys.empty() ? 0 : bucketAt(keys.size() - 1) + 1;
    std::fill(starts_.begin() + static_cast<std::ptrdiff_t>(after), starts_.end(),
              static_cast<std::uint32_t>(keys.size()));
  }

  /// Writes the point samples in the box centre +- half that `keep(entry)` accepts into
  /// `out` from index 0, in a fixed order, as Neighbours (same_label: the entry's label is
  /// `occupied`), and returns how many; `out` only grows, its elements past the count are
  /// scratch. No branch per entry: each is written, and kept when inside and accepted (the box
  /// test, passed by about a third of the entries, would be mispredicted about every other).
  template <class Keep>
  std::size_t neighboursInBox(const Eigen::Vector3d& centre, double half, bool occupied,
                              Keep&& keep, std::vector<Neighbour>& out) const {
    if (entries_.empty()) return 0;
    const auto lo = cellOf(centre.array() - half);
    const auto hi = cellOf(centre.array() + half);
    std::size_t n = 0;
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
        const std::int64_t row = (z * n_[1] + y) * n_[0];
        const std::uint32_t from = starts_[static_cast<std::size_t>(row + lo[0])];
        const std::uint32_t to = starts_[static_cast<std::size_t>(row + hi[0] + 1)];
        if (out.size() < n + (to - from)) out.resize(2 * (n + (to - from)));
        Neighbour* const written = out.data();
        for (std::uint32_t o = from; o < to; ++o) {
          const Entry& e = entries_[o];
          const Eigen::Array3d d = (e.x - centre).array().abs();
          const bool inside = (d[0] <= half) & (d[1] <= half) & (d[2] <= half);
          written[n] = {e.x, e.occupied == occupied};
          n += static_cast<std::size_t>(inside & keep(e));
        }
      }
    }
    return n;
  }

 private:
  [[nodiscard]] std::size_t cellCount(const Eigen::Vector3d& size) const {
    double n = 1.0;
    for (int a = 0; a < 3; ++a) n *= std::floor(size[a] / cell_) + 1.0;
    return n > 1e18 ? std::numeric_limits<std::size_t>::max() : static_cast<std::size_t>(n);
  }
  /// The bucket of p, clamped into the grid.
  [[nodiscard]] std::array<std::int64_t, 3> cellOf(const Eigen::Array3d& p) const {
    std::array<std::int64_t, 3> c{};
    for (int a = 0; a < 3; ++a) {
      // floor, clamped: below 1 the bucket is 0, and from there on the truncation is the floor
      // (std::floor without SSE4.1 is a sequence of ~25 instructions).
      const double v = (p[a] - min_[a]) / cell_;
      c[a] = v < 1.0 ? 0
                     : (v >= static_cast<double>(n_[a]) ? n_[a] - 1 : static_cast<std::int64_t>(v));
    }
    return c;
  }

  std::vector<std::uint32_t>& starts_;
  std::vector<Entry>& entries_;
  double cell_ = 1.0;
  Eigen::Vector3d min_ = Eigen::Vector3d::Zero();
  std::int64_t n_[3] = {1, 1, 1};
};

}  // namespace densemap::kernel::detail
