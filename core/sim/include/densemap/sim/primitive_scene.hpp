#pragma once

#include <cstdint>
#include <vector>

#include "densemap/sim/scene.hpp"

namespace densemap {

struct BoxShape {  // axis-aligned solid box
  Eigen::Vector3d min, max;
};
struct CylinderShape {  // vertical solid cylinder
  Eigen::Vector2d center_xy;
  double radius;
  double z_min, z_max;
};
struct SphereShape {
  Eigen::Vector3d center;
  double radius;
};

/// A scene of analytic solids: boxes, vertical cylinders and spheres.
class PrimitiveScene final : public Scene {
 public:
  explicit PrimitiveScene(const Eigen::AlignedBox3d& bounds) : bounds_(bounds) {}

  void add(const BoxShape& b);
  void add(const CylinderShape& c);
  void add(const SphereShape& s);

  [[nodiscard]] std::optional<double> castRay(const Eigen::Vector3d& origin,
                                              const Eigen::Vector3d& direction,
                                              double max_range_m) const override;
  [[nodiscard]] bool overlapsBox(const Eigen::Vector3d& min,
                                 const Eigen::Vector3d& max) const override;
  [[nodiscard]] Eigen::AlignedBox3d bounds() const override { return bounds_; }
  [[nodiscard]] std::size_t primitiveCount() const {
    return boxes_.size() + cylinders_.size() + spheres_.size();
  }

 private:
  // Primitives by slab of kSlabM metres along x, so a ray only meets the primitives of the
  // slabs its segment crosses (a long street stays as fast to scan as a short one).
  static constexpr double kSlabM = 16.0;
  struct Slab {
    std::vector<std::uint32_t> boxes, cylinders, spheres;
  };
  void index(double x_min, double x_max, std::vector<std::uint32_t> Slab::*list, std::uint32_t id);
  [[nodiscard]] int slabOf(double x) const;

  Eigen::AlignedBox3d bounds_;
  std::vector<Slab> slabs_;
  std::vector<BoxShape> boxes_;
  std::vector<CylinderShape> cylinders_;
  std::vector<SphereShape> spheres_;
};

}  // namespace densemap
