#pragma once

#include <cstdint>
#include <functional>

namespace densemap {

/// Address of one voxel at the finest level, laid out like OctoMap's `OcTreeKey`: 16 bits per
/// axis, key 32768 is the voxel whose lower corner is the world origin.
struct VoxelKey {
  std::uint16_t x = 0;
  std::uint16_t y = 0;
  std::uint16_t z = 0;

  [[nodiscard]] std::uint16_t operator[](int axis) const {
    return axis == 0 ? x : axis == 1 ? y : z;
  }
  [[nodiscard]] std::uint16_t& operator[](int axis) { return axis == 0 ? x : axis == 1 ? y : z; }

  /// 48-bit packing, usable as a hash key and as a total order (z major).
  [[nodiscard]] std::uint64_t packed() const {
    return (std::uint64_t{z} << 32) | (std::uint64_t{y} << 16) | std::uint64_t{x};
  }
  [[nodiscard]] static VoxelKey fromPacked(std::uint64_t p) {
    return {static_cast<std::uint16_t>(p & 0xffff), static_cast<std::uint16_t>((p >> 16) & 0xffff),
            static_cast<std::uint16_t>((p >> 32) & 0xffff)};
  }

  friend bool operator==(const VoxelKey&, const VoxelKey&) = default;
};

struct VoxelKeyHash {
  [[nodiscard]] std::size_t operator()(const VoxelKey& k) const {
    // Same mixing as OctoMap's OcTreeKey::KeyHash: cheap and good for spatial keys.
    return static_cast<std::size_t>(k.x) + 1447 * static_cast<std::size_t>(k.y) +
           345637 * static_cast<std::size_t>(k.z);
  }
};

}  // namespace densemap
