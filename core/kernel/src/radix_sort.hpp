#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/geometry/block_layout.hpp"

namespace densemap::kernel {

/// Sorts `items` by key(item) (an unsigned integer below 2^key_bits), stably: a least
/// significant digit radix sort, 11 bits a pass, each pass counted and placed in parallel by
/// fixed chunks of the items, so the order never depends on the thread count. `scratch` is a
/// buffer the caller keeps between calls. Several times faster than a comparison sort of the
/// few hundred thousand (key, index) pairs of a scan.
template <class T, class KeyOf>
void radixSort(std::vector<T>& items, std::vector<T>& scratch, int key_bits, KeyOf&& key,
               std::vector<std::uint32_t>& counts) {
  constexpr int kBits = 11;
  constexpr std::size_t kBins = std::size_t{1} << kBits;
  constexpr std::size_t kChunk = 32768;
  const std::size_t n = items.size();
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  scratch.resize(n);
  for (int shift = 0; shift < key_bits; shift += kBits) {
    const auto digit = [&key, shift](const T& item) {
      return static_cast<std::size_t>((key(item) >> shift) & (kBins - 1));
    };
    counts.assign(chunks * kBins, 0);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::uint32_t* mine = counts.data() + c * kBins;
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i)
        ++mine[digit(items[i])];
    });
    // Exclusive offsets, digit major, chunk minor: stable.
    std::uint32_t sum = 0;
    for (std::size_t d = 0; d < kBins; ++d) {
      for (std::size_t c = 0; c < chunks; ++c) {
        const std::uint32_t k = counts[c * kBins + d];
        counts[c * kBins + d] = sum;
        sum += k;
      }
    }
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::uint32_t* mine = counts.data() + c * kBins;
      for (std::size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
        scratch[mine[digit(items[i])]++] = items[i];
      }
    });
    items.swap(scratch);
  }
}

/// Voxel keys ranked in a window of the grid: the keys within `reach` voxels of a centre, each
/// axis' offset in just the bits the window needs, z major, then y, then x: the order of
/// VoxelKey::packed, so a radix sort by rank puts the keys in the packed keys' order, and a
/// scan's hits (within max range of its origin) sort in 3 passes of 11 bits, not 5 for the
/// packing's 48 and the one above it. outside() ranks above every key of the window.
class KeyWindow {
 public:
  /// The window of the keys within max_range (m) of `centre` on `grid`, when it needs fewer
  /// bits than the packing (nullopt: no max range, or the centre is outside the grid).
  [[nodiscard]] static std::optional<KeyWindow> around(const VoxelGrid& grid,
                                                       const Eigen::Vector3d& centre,
                                                       double max_range) {
    if (!(max_range >= 0.0) || !std::isfinite(max_range)) return std::nullopt;
    const auto key = grid.pointToKey(centre.cast<float>());
    const double voxels = std::ceil(max_range / grid.resolution()) + 2.0;
    if (!key || !(voxels < 16384.0)) return std::nullopt;
    return KeyWindow(*key, static_cast<int>(voxels));
  }
  /// Bits of a rank (outside() included).
  [[nodiscard]] int bits() const { return 3 * axis_bits_ + 1; }
  [[nodiscard]] std::uint64_t outside() const { return std::uint64_t{1} << (3 * axis_bits_); }
  /// The rank of `key`; nullopt when it lies outside the window.
  [[nodiscard]] std::optional<std::uint64_t> rank(const VoxelKey& key) const {
    const int offset[3] = {key.x - low_[0], key.y - low_[1], key.z - low_[2]};
    std::uint64_t r = 0;
    for (int a = 2; a >= 0; --a) {
      if (offset[a] < 0 || offset[a] > span_) return std::nullopt;
      r = (r << axis_bits_) | static_cast<std::uint64_t>(offset[a]);
    }
    return r;
  }

 private:
  KeyWindow(const VoxelKey& centre, int reach)
      : low_{centre.x - reach, centre.y - reach, centre.z - reach},
        span_(2 * reach),
        axis_bits_(static_cast<int>(std::bit_width(static_cast<unsigned>(2 * reach)))) {}
  int low_[3];
  int span_;
  int axis_bits_;
};

/// Blocks ranked in a box of them (each axis' offset in the bits the box needs, z major: the
/// order of block keys, block::blockOf), so that a scan's (block, kernel) pairs sort in two
/// radix passes of 11 bits instead of four for the keys' 39.
struct BlockRanks {
  std::array<std::uint64_t, 3> low{};  // the box's least block coordinates
  int bits_x = 0, bits_y = 0, bits_z = 0;
  [[nodiscard]] int bits() const { return bits_x + bits_y + bits_z; }
  [[nodiscard]] std::uint64_t rank(std::uint64_t bx, std::uint64_t by, std::uint64_t bz) const {
    return ((bz - low[2]) << (bits_x + bits_y)) | ((by - low[1]) << bits_x) | (bx - low[0]);
  }
  /// The block key (block::blockOf) of a rank.
  [[nodiscard]] std::uint64_t blockKey(std::uint64_t rank) const {
    const std::uint64_t mask_x = (std::uint64_t{1} << bits_x) - 1;
    const std::uint64_t mask_y = (std::uint64_t{1} << bits_y) - 1;
    const auto corner = [](std::uint64_t coordinate) {
      return static_cast<std::uint16_t>(coordinate << block::kShift);
    };
    return block::blockOf(VoxelKey{corner((rank & mask_x) + low[0]),
                                   corner(((rank >> bits_x) & mask_y) + low[1]),
                                   corner((rank >> (bits_x + bits_y)) + low[2])});
  }
};

/// Items 0 .. n - 1 by voxel: pairs[p] = (a voxel's key, item), sorted by voxel (the packed
/// keys' order), items in order within each; key_of(i) is item i's voxel (nullopt: none; those
/// come last, their keys all equal to the value returned). Ranked in `window` where every
/// voxel lies in it (see KeyWindow), else packed (VoxelKey::packed, none 2^48): only equality
/// and that value are to be read from the keys.
template <class KeyOf>
std::uint64_t sortByVoxel(std::size_t n, KeyOf&& key_of, const std::optional<KeyWindow>& window,
                          std::vector<std::pair<std::uint64_t, std::uint32_t>>& pairs,
                          std::vector<std::pair<std::uint64_t, std::uint32_t>>& scratch,
                          std::vector<std::uint32_t>& counts) {
  pairs.resize(n);
  const auto fill = [&](auto&& keyOfVoxel, std::uint64_t none) {
    std::atomic<bool> escaped{false};
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          std::uint64_t k = none;
                          if (const std::optional<VoxelKey> voxel = key_of(i)) {
                            const std::optional<std::uint64_t> ranked = keyOfVoxel(*voxel);
                            if (!ranked) escaped = true;
                            k = ranked.value_or(none);
                          }
                          pairs[i] = {k, static_cast<std::uint32_t>(i)};
                        }
                      });
    return !escaped.load();
  };
  if (window && fill([&](const VoxelKey& v) { return window->rank(v); }, window->outside())) {
    radixSort(
        pairs, scratch, window->bits(), [](const auto& pair) { return pair.first; }, counts);
    return window->outside();
  }
  const std::uint64_t none = std::uint64_t{1} << 48;
  fill([](const VoxelKey& v) { return std::optional<std::uint64_t>(v.packed()); }, none);
  radixSort(
      pairs, scratch, 49, [](const auto& pair) { return pair.first; }, counts);
  return none;
}

}  // namespace densemap::kernel
