#include "densemap/sim/walker_scene.hpp"

#include <algorithm>
#include <cmath>

namespace densemap {
namespace {

constexpr double kRadiusM = 0.25;
constexpr double kHeightM = 1.8;
constexpr double kSpeedMps = 1.4;
constexpr double kPaceM = 16.0;
constexpr double kSideM = 2.5;

}  // namespace

std::vector<CylinderShape> walkersAt(const std::vector<Transform>& poses, int count, double t_s) {
  std::vector<CylinderShape> out;
  if (poses.empty() || count <= 0) return out;
  const auto n = static_cast<long>(poses.size());
  for (int k = 0; k < count; ++k) {
    const long at = std::clamp<long>((k + 1) * n / (count + 1), 0, n - 1);
    const Eigen::Vector3d before = poses[static_cast<std::size_t>(std::max<long>(at - 1, 0))].translation();
    const Eigen::Vector3d after = poses[static_cast<std::size_t>(std::min(at + 1, n - 1))].translation();
    Eigen::Vector2d along = (after - before).head<2>();
    along = along.norm() > 1e-9 ? along.normalized() : Eigen::Vector2d::UnitX();
    const Eigen::Vector2d left(-along.y(), along.x());
    const Eigen::Vector2d centre = poses[static_cast<std::size_t>(at)].translation().head<2>() +
                                   (k % 2 == 0 ? kSideM : -kSideM) * left;
    // A triangle wave over [-kPaceM / 2, kPaceM / 2], starting at one end.
    const double phase = std::fmod(kSpeedMps * t_s, 2.0 * kPaceM);
    const double s = (phase < kPaceM ? phase : 2.0 * kPaceM - phase) - kPaceM / 2.0;
    out.push_back({centre + s * along, kRadiusM, 0.0, kHeightM});
  }
  return out;
}

WalkerScene::WalkerScene(const Scene& base, const std::vector<CylinderShape>& walkers)
    : base_(base), walkers_(base.bounds()) {
  for (const CylinderShape& c : walkers) walkers_.add(c);
}

std::optional<double> WalkerScene::castRay(const Eigen::Vector3d& origin,
                                           const Eigen::Vector3d& direction,
                                           double max_range_m) const {
  const auto wall = base_.castRay(origin, direction, max_range_m);
  const auto walker = walkers_.castRay(origin, direction, wall.value_or(max_range_m));
  return walker ? walker : wall;
}

}  // namespace densemap
