#pragma once

#include <cmath>
#include <optional>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/rounding.hpp"
#include "densemap/geometry/voxel_key.hpp"

namespace densemap {

/// Conversions between metric coordinates and voxel keys, bit-for-bit those of OctoMap 1.9.7
/// (`OcTreeBaseImpl::coordToKeyChecked`, `keyToCoord`) at the finest depth (16).
/// Immutable after construction; thread-safe.
class VoxelGrid {
 public:
  static constexpr int kMaxKey = 32768;  // OctoMap's tree_max_val for depth 16.

  /// Aborts unless resolution_m is finite and positive.
  explicit VoxelGrid(double resolution_m);

  [[nodiscard]] double resolution() const { return resolution_m_; }
  /// 1 / resolution as OctoMap stores it: coordToKey floors coordinate * this.
  [[nodiscard]] double resolutionFactor() const { return resolution_factor_; }
  /// Half the extent of the addressable cube per axis, in metres.
  [[nodiscard]] double halfExtent() const { return kMaxKey * resolution_m_; }

  /// Key of one coordinate; std::nullopt outside the addressable range or for NaN.
  [[nodiscard]] std::optional<std::uint16_t> coordToKey(double coordinate) const {
    // OcTreeBaseImpl::coordToKeyChecked: floor in double, after promoting the float coordinate.
    // floor(s) lies in [-kMaxKey, kMaxKey) exactly when s does.
    const double scaled = resolution_factor_ * coordinate;
    if (!(scaled >= -kMaxKey && scaled < kMaxKey)) return std::nullopt;
    return static_cast<std::uint16_t>(floorToInt(scaled) + kMaxKey);
  }
  [[nodiscard]] std::optional<VoxelKey> pointToKey(const Point3f& p) const {
    const auto x = coordToKey(p.x());
    const auto y = coordToKey(p.y());
    const auto z = coordToKey(p.z());
    if (!x || !y || !z) return std::nullopt;
    return VoxelKey{*x, *y, *z};
  }

  /// Centre of the voxel along one axis (double, as OctoMap computes it).
  [[nodiscard]] double keyToCoord(std::uint16_t key) const {
    return keyToCoord(static_cast<int>(key), resolution_m_);
  }
  /// The same at `resolution_m` (for loops that keep the resolution in a register).
  [[nodiscard]] static double keyToCoord(int key, double resolution_m) {
    return (static_cast<double>(key - kMaxKey) + 0.5) * resolution_m;
  }
  [[nodiscard]] Point3f keyToPoint(const VoxelKey& k) const {
    return {static_cast<float>(keyToCoord(k.x)), static_cast<float>(keyToCoord(k.y)),
            static_cast<float>(keyToCoord(k.z))};
  }

  friend bool operator==(const VoxelGrid& a, const VoxelGrid& b) {
    return a.resolution_m_ == b.resolution_m_;
  }

 private:
  double resolution_m_;
  double resolution_factor_;
};

}  // namespace densemap
