#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/geometry/voxel_key.hpp"

namespace densemap::block {

/// Voxels are grouped in cubes of 8^3 for storage and for per-scan update sets; a block is
/// named by the key bits above the lowest three, packed into 39 bits.
inline constexpr int kShift = 3;
inline constexpr int kEdge = 1 << kShift;
inline constexpr int kVoxels = kEdge * kEdge * kEdge;
inline constexpr int kMaskWords = kVoxels / 64;

/// One bit per voxel of a block, indexed by indexOf().
using BlockMask = std::array<std::uint64_t, kMaskWords>;

inline void setBit(BlockMask& m, int index) { m[index >> 6] |= std::uint64_t{1} << (index & 63); }
inline void clearBit(BlockMask& m, int index) {
  m[index >> 6] &= ~(std::uint64_t{1} << (index & 63));
}
[[nodiscard]] inline bool testBit(const BlockMask& m, int index) {
  return ((m[index >> 6] >> (index & 63)) & 1U) != 0;
}

namespace detail {
/// The set bits of words[0, n), with std::popcount as the build's baseline target compiles it
/// (x86-64 without POPCNT: a libgcc call per word).
[[nodiscard]] inline std::size_t countBitsPortable(const std::uint64_t* words, std::size_t n) {
  std::size_t bits = 0;
  for (std::size_t i = 0; i < n; ++i) bits += static_cast<std::size_t>(std::popcount(words[i]));
  return bits;
}
#if defined(__x86_64__) && defined(__GNUC__)
/// The same with the POPCNT instruction (every x86-64 processor since 2008; the baseline
/// target may not assume it, hence the run-time check in countBits).
[[gnu::target("popcnt")]] inline std::size_t countBitsPopcnt(const std::uint64_t* words,
                                                             std::size_t n) {
  std::size_t bits = 0;
  for (std::size_t i = 0; i < n; ++i) {
    bits += static_cast<std::size_t>(__builtin_popcountll(words[i]));
  }
  return bits;
}
[[nodiscard]] inline bool hasPopcnt() {
  static const bool has = [] {
    __builtin_cpu_init();
    return __builtin_cpu_supports("popcnt") != 0;
  }();
  return has;
}
#endif
}  // namespace detail

/// The set bits of words[0, n): the POPCNT instruction where the processor has it (checked at
/// run time), else the portable count (libgcc's software popcount is slow enough to show in
/// the culling region's sweep).
[[nodiscard]] inline std::size_t countBits(const std::uint64_t* words, std::size_t n) {
#if defined(__x86_64__) && defined(__GNUC__)
  if (detail::hasPopcnt()) return detail::countBitsPopcnt(words, n);
#endif
  return detail::countBitsPortable(words, n);
}

[[nodiscard]] inline std::size_t countBits(const BlockMask& m) {
  return countBits(m.data(), m.size());
}
/// Whether any bit of `m` is set.
[[nodiscard]] inline bool anyBit(const BlockMask& m) {
  std::uint64_t any = 0;
  for (const std::uint64_t w : m) any |= w;
  return any != 0;
}

/// Calls f(index) for every set bit of `m`, in increasing index order.
template <class F>
void forEachSetBit(const BlockMask& m, F&& f) {
  for (int w = 0; w < kMaskWords; ++w) {
    for (std::uint64_t bits = m[w]; bits != 0; bits &= bits - 1) f(w * 64 + std::countr_zero(bits));
  }
}

[[nodiscard]] inline std::uint64_t blockOf(const VoxelKey& k) {
  return (std::uint64_t{static_cast<std::uint16_t>(k.x >> kShift)}) |
         (std::uint64_t{static_cast<std::uint16_t>(k.y >> kShift)} << 13) |
         (std::uint64_t{static_cast<std::uint16_t>(k.z >> kShift)} << 26);
}

[[nodiscard]] inline int indexOf(const VoxelKey& k) {
  constexpr int m = kEdge - 1;
  return (k.x & m) | ((k.y & m) << kShift) | ((k.z & m) << (2 * kShift));
}

/// blockOf(VoxelKey::fromPacked(packed)) and indexOf(..) straight from the packed key (16 bits an
/// axis: x, y, z from bit 0): masks and shifts, for loops over many packed keys.
[[nodiscard]] inline std::uint64_t blockOfPacked(std::uint64_t packed) {
  static_assert(kShift == 3);
  return ((packed >> 3) & 0x1fff) | ((packed >> 6) & (std::uint64_t{0x1fff} << 13)) |
         ((packed >> 9) & (std::uint64_t{0x1fff} << 26));
}

[[nodiscard]] inline int indexOfPacked(std::uint64_t packed) {
  static_assert(kShift == 3);
  return static_cast<int>((packed & 7) | ((packed >> 13) & (7 << 3)) | ((packed >> 26) & (7 << 6)));
}

[[nodiscard]] inline VoxelKey keyOf(std::uint64_t block, int index) {
  constexpr int m = kEdge - 1;
  return {
      static_cast<std::uint16_t>(((block & 0x1fff) << kShift) | (index & m)),
      static_cast<std::uint16_t>((((block >> 13) & 0x1fff) << kShift) | ((index >> kShift) & m)),
      static_cast<std::uint16_t>((((block >> 26) & 0x1fff) << kShift) |
                                 ((index >> (2 * kShift)) & m))};
}

/// A block's coordinates (its key's three 13-bit fields: x, y, z).
[[nodiscard]] inline std::array<std::uint32_t, 3> coordsOf(std::uint64_t block) {
  return {static_cast<std::uint32_t>(block & 0x1fff),
          static_cast<std::uint32_t>((block >> 13) & 0x1fff),
          static_cast<std::uint32_t>((block >> 26) & 0x1fff)};
}

/// A box of blocks, inclusive, in block coordinates.
struct BlockBox {
  std::array<std::uint32_t, 3> min{}, max{};
  /// Every block there is.
  [[nodiscard]] static BlockBox all() { return {{0, 0, 0}, {0x1fff, 0x1fff, 0x1fff}}; }
  [[nodiscard]] bool contains(std::uint64_t block) const {
    const auto c = coordsOf(block);
    for (int a = 0; a < 3; ++a) {
      if (c[a] < min[a] || c[a] > max[a]) return false;
    }
    return true;
  }
};

/// A block's centre: its corner cell's centre plus half a block less half a cell. The one
/// definition eviction uses (every map kind evicts the same blocks).
[[nodiscard]] inline Point3f centreOf(const VoxelGrid& grid, std::uint64_t block) {
  const double half = 0.5 * kEdge;
  return grid.keyToPoint(keyOf(block, 0)) +
         Point3f::Constant(static_cast<float>((half - 0.5) * grid.resolution()));
}

/// Whether a box [lo, hi] keeps the block centred at `centre`: a block belongs to the box its
/// centre lies in, faces included (map.bounds' eviction, and which shard holds a cell).
[[nodiscard]] inline bool boxKeeps(const Point3f& lo, const Point3f& hi, const Point3f& centre) {
  return (centre.array() >= lo.array()).all() && (centre.array() <= hi.array()).all();
}

/// How far outside a box the cells of the blocks it keeps may lie, m: half a block, and a cell
/// more for a ray that grazes a kept cell's corner.
[[nodiscard]] inline double boxKeepMargin(double resolution_m) {
  return resolution_m * (kEdge / 2 + 1);
}

}  // namespace densemap::block

namespace densemap {

/// Some cells of one block: a dense map's cells reached by a scan (GridMap::assignBlocks).
struct BlockCells {
  std::uint64_t key = 0;
  block::BlockMask cells{};
};

}  // namespace densemap
