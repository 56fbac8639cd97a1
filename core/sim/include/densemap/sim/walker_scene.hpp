#pragma once

#include <vector>

#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/sim/primitive_scene.hpp"

namespace densemap {

/// People walking beside the sensor's path (SequenceOptions::walkers), at `t_s` seconds into
/// the sequence: `count` upright cylinders, 0.25 m in radius and 1.8 m tall, standing on z = 0.
/// Walker k paces 16 m back and forth at 1.4 m/s along the path, 2.5 m to its left (sides
/// alternate), centred where the sensor is at (k + 1) / (count + 1) of the poses.
[[nodiscard]] std::vector<CylinderShape> walkersAt(const std::vector<Transform>& poses, int count,
                                                   double t_s);

/// A static scene with moving solids in it (the walkers at one instant): rays meet the nearer
/// of the two; the ground truth (overlapsBox, bounds) is the static scene's alone, so a map
/// that keeps a walker's old places shows them as cells the truth does not have.
class WalkerScene final : public Scene {
 public:
  WalkerScene(const Scene& base, const std::vector<CylinderShape>& walkers);

  [[nodiscard]] std::optional<double> castRay(const Eigen::Vector3d& origin,
                                              const Eigen::Vector3d& direction,
                                              double max_range_m) const override;
  [[nodiscard]] bool overlapsBox(const Eigen::Vector3d& min,
                                 const Eigen::Vector3d& max) const override {
    return base_.overlapsBox(min, max);
  }
  [[nodiscard]] Eigen::AlignedBox3d bounds() const override { return base_.bounds(); }

 private:
  const Scene& base_;
  PrimitiveScene walkers_;
};

}  // namespace densemap
