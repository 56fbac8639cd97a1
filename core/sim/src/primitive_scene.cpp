#include "densemap/sim/primitive_scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace densemap {
namespace {

constexpr double kEpsilon = 1e-9;

// Slab method; the entry distance if the ray enters the box ahead of the origin.
std::optional<double> hitBox(const BoxShape& b, const Eigen::Vector3d& o,
                             const Eigen::Vector3d& d) {
  double t_near = -std::numeric_limits<double>::infinity();
  double t_far = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < kEpsilon) {
      if (o[a] < b.min[a] || o[a] > b.max[a]) return std::nullopt;
      continue;
    }
    double t0 = (b.min[a] - o[a]) / d[a];
    double t1 = (b.max[a] - o[a]) / d[a];
    if (t0 > t1) std::swap(t0, t1);
    t_near = std::max(t_near, t0);
    t_far = std::min(t_far, t1);
  }
  if (t_near > t_far || t_near <= kEpsilon) return std::nullopt;
  return t_near;
}

std::optional<double> hitCylinder(const CylinderShape& c, const Eigen::Vector3d& o,
                                  const Eigen::Vector3d& d) {
  double best = std::numeric_limits<double>::infinity();
  const double ox = o.x() - c.center_xy.x(), oy = o.y() - c.center_xy.y();
  const double a = d.x() * d.x() + d.y() * d.y();
  if (a > kEpsilon) {  // side wall
    const double b = 2 * (ox * d.x() + oy * d.y());
    const double cc = ox * ox + oy * oy - c.radius * c.radius;
    const double disc = b * b - 4 * a * cc;
    if (disc >= 0) {
      const double t = (-b - std::sqrt(disc)) / (2 * a);
      const double z = o.z() + t * d.z();
      if (t > kEpsilon && z >= c.z_min && z <= c.z_max) best = t;
    }
  }
  if (std::abs(d.z()) > kEpsilon) {  // caps
    for (const double zc : {c.z_min, c.z_max}) {
      const double t = (zc - o.z()) / d.z();
      const double x = ox + t * d.x(), y = oy + t * d.y();
      if (t > kEpsilon && x * x + y * y <= c.radius * c.radius) best = std::min(best, t);
    }
  }
  if (!std::isfinite(best)) return std::nullopt;
  return best;
}

std::optional<double> hitSphere(const SphereShape& s, const Eigen::Vector3d& o,
                                const Eigen::Vector3d& d) {
  const Eigen::Vector3d oc = o - s.center;
  const double b = oc.dot(d);
  const double c = oc.squaredNorm() - s.radius * s.radius;
  const double disc = b * b - c;
  if (disc < 0) return std::nullopt;
  const double t = -b - std::sqrt(disc);
  if (t <= kEpsilon) return std::nullopt;
  return t;
}

double clampTo(double v, double lo, double hi) { return std::max(lo, std::min(v, hi)); }

}  // namespace

std::optional<double> PrimitiveScene::castRay(const Eigen::Vector3d& origin,
                                              const Eigen::Vector3d& direction,
                                              double max_range_m) const {
  double best = max_range_m;
  bool hit = false;
  auto consider = [&](std::optional<double> t) {
    if (t && *t < best) {
      best = *t;
      hit = true;
    }
  };
  // Every point the ray can hit lies in the x extent of its segment.
  const double x_far = origin.x() + direction.x() * max_range_m;
  const int first = std::isfinite(x_far) ? slabOf(std::min(origin.x(), x_far)) : 0;
  const int last = std::isfinite(x_far) ? slabOf(std::max(origin.x(), x_far))
                                        : static_cast<int>(slabs_.size()) - 1;
  for (int i = first; i <= last; ++i) {
    const Slab& slab = slabs_[static_cast<std::size_t>(i)];
    for (const auto b : slab.boxes) consider(hitBox(boxes_[b], origin, direction));
    for (const auto c : slab.cylinders) consider(hitCylinder(cylinders_[c], origin, direction));
    for (const auto s : slab.spheres) consider(hitSphere(spheres_[s], origin, direction));
  }
  if (!hit) return std::nullopt;
  return best;
}

int PrimitiveScene::slabOf(double x) const {
  const double i = std::floor((x - bounds_.min().x()) / kSlabM);
  return static_cast<int>(std::clamp(i, 0.0, static_cast<double>(slabs_.size()) - 1.0));
}

void PrimitiveScene::index(double x_min, double x_max, std::vector<std::uint32_t> Slab::*list,
                           std::uint32_t id) {
  if (slabs_.empty()) {
    const double extent = std::max(bounds_.max().x() - bounds_.min().x(), kSlabM);
    slabs_.resize(static_cast<std::size_t>(std::ceil(extent / kSlabM)) + 1);
  }
  for (int i = slabOf(x_min); i <= slabOf(x_max); ++i) {
    (slabs_[static_cast<std::size_t>(i)].*list).push_back(id);
  }
}

void PrimitiveScene::add(const BoxShape& b) {
  index(b.min.x(), b.max.x(), &Slab::boxes, static_cast<std::uint32_t>(boxes_.size()));
  boxes_.push_back(b);
}

void PrimitiveScene::add(const CylinderShape& c) {
  index(c.center_xy.x() - c.radius, c.center_xy.x() + c.radius, &Slab::cylinders,
        static_cast<std::uint32_t>(cylinders_.size()));
  cylinders_.push_back(c);
}

void PrimitiveScene::add(const SphereShape& s) {
  index(s.center.x() - s.radius, s.center.x() + s.radius, &Slab::spheres,
        static_cast<std::uint32_t>(spheres_.size()));
  spheres_.push_back(s);
}

bool PrimitiveScene::overlapsBox(const Eigen::Vector3d& min, const Eigen::Vector3d& max) const {
  for (const auto& b : boxes_) {
    if ((b.min.array() < max.array()).all() && (b.max.array() > min.array()).all()) return true;
  }
  for (const auto& c : cylinders_) {
    if (c.z_min >= max.z() || c.z_max <= min.z()) continue;
    const double dx = c.center_xy.x() - clampTo(c.center_xy.x(), min.x(), max.x());
    const double dy = c.center_xy.y() - clampTo(c.center_xy.y(), min.y(), max.y());
    if (dx * dx + dy * dy < c.radius * c.radius) return true;
  }
  for (const auto& s : spheres_) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = s.center[a] - clampTo(s.center[a], min[a], max[a]);
      d2 += d * d;
    }
    if (d2 < s.radius * s.radius) return true;
  }
  return false;
}

}  // namespace densemap
