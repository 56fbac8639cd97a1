#pragma once

#include <Eigen/Geometry>
#include <optional>

namespace densemap {

/// Something a simulated LiDAR can see, in the world frame (metres).
/// Thread-safety: const methods are safe to call concurrently.
class Scene {
 public:
  virtual ~Scene() = default;
  /// Distance along the unit `direction` to the first surface within `max_range_m`.
  [[nodiscard]] virtual std::optional<double> castRay(const Eigen::Vector3d& origin,
                                                      const Eigen::Vector3d& direction,
                                                      double max_range_m) const = 0;
  /// Whether any solid overlaps the open box (min, max): the ground truth of a voxel.
  [[nodiscard]] virtual bool overlapsBox(const Eigen::Vector3d& min,
                                         const Eigen::Vector3d& max) const = 0;
  /// The region ground truth is written for.
  [[nodiscard]] virtual Eigen::AlignedBox3d bounds() const = 0;
};

}  // namespace densemap
