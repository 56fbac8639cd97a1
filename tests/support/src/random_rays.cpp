#include "densemap/test_support/random_rays.hpp"

#include <cmath>

namespace densemap::test {

float RandomRays::coordinate(bool on_plane) {
  std::uniform_real_distribution<double> u(-extent_m_, extent_m_);
  if (!on_plane) return static_cast<float>(u(rng_));
  // A multiple of the resolution, as the float a user would type or compute.
  return static_cast<float>(std::round(u(rng_) / resolution_m_) * resolution_m_);
}

Point3f RandomRays::point(double p_plane) {
  std::bernoulli_distribution plane(p_plane);
  return {coordinate(plane(rng_)), coordinate(plane(rng_)), coordinate(plane(rng_))};
}

Ray RandomRays::next(RayKind kind) {
  switch (kind) {
    case RayKind::kUniform:
      return {point(0.0), point(0.0)};
    case RayKind::kOnFaces: {
      Ray r{point(0.3), point(0.0)};
      std::uniform_int_distribution<int> axis(0, 2);
      r.end[axis(rng_)] = coordinate(true);
      return r;
    }
    case RayKind::kOnEdges: {
      Ray r{point(0.3), point(0.0)};
      std::uniform_int_distribution<int> axis(0, 2);
      const int skip = axis(rng_);
      for (int a = 0; a < 3; ++a) {
        if (a != skip) r.end[a] = coordinate(true);
      }
      return r;
    }
    case RayKind::kOnCorners:
      return {point(0.5), point(1.0)};
    case RayKind::kAxisAligned: {
      Ray r{point(0.2), Point3f::Zero()};
      r.end = r.origin;
      std::uniform_int_distribution<int> axis(0, 2);
      std::bernoulli_distribution two(0.3);
      r.end[axis(rng_)] = coordinate(false);
      if (two(rng_)) r.end[axis(rng_)] = coordinate(true);
      return r;
    }
    case RayKind::kZeroLength: {
      const Point3f p = point(0.5);
      return {p, p};
    }
    case RayKind::kOriginOnPlane:
      return {point(1.0), point(0.2)};
    case RayKind::kShort: {
      Ray r{point(0.3), Point3f::Zero()};
      std::uniform_real_distribution<double> d(-2.0 * resolution_m_, 2.0 * resolution_m_);
      for (int a = 0; a < 3; ++a) r.end[a] = static_cast<float>(r.origin[a] + d(rng_));
      return r;
    }
  }
  return {point(0.0), point(0.0)};
}

}  // namespace densemap::test

namespace densemap::test {

PointCloud adversarialScan(double resolution_m, const Point3f& origin, int n, double far_m,
                           unsigned seed) {
  std::mt19937_64 rng(seed);
  RandomRays planes(resolution_m, far_m * 0.7, seed + 1);
  std::uniform_int_distribution<int> kind(0, 9);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> axis(0, 2);
  PointCloud cloud;
  cloud.reserve(n);
  const Point3f dense_cell = origin + Point3f(1.234F, -0.77F, 0.31F);
  for (int i = 0; i < n; ++i) {
    switch (kind(rng)) {
      case 0:
        cloud.push_back(planes.point(1.0));  // corners
        break;
      case 1:
        cloud.push_back(planes.point(0.6));  // faces and edges
        break;
      case 2: {  // axis-parallel from the origin
        Point3f p = origin;
        p[axis(rng)] += static_cast<float>(u(rng) * far_m * 0.8);
        cloud.push_back(p);
        break;
      }
      case 3: {  // many points in one small cell-sized region
        cloud.push_back(dense_cell + Point3f(static_cast<float>(u(rng) * resolution_m * 0.4),
                                             static_cast<float>(u(rng) * resolution_m * 0.4),
                                             static_cast<float>(u(rng) * resolution_m * 0.4)));
        break;
      }
      case 4: {  // beyond the far range
        Point3f d(static_cast<float>(u(rng)), static_cast<float>(u(rng)),
                  static_cast<float>(u(rng)));
        if (d.norm() < 1e-3F) d = Point3f(1, 0, 0);
        cloud.push_back(origin +
                        d.normalized() * static_cast<float>(far_m * (1.05 + u(rng) * 0.3 + 0.3)));
        break;
      }
      case 5:
        cloud.push_back(i % 50 == 0 ? origin : planes.point(0.0));
        break;
      default: {
        Point3f d(static_cast<float>(u(rng)), static_cast<float>(u(rng)),
                  static_cast<float>(u(rng)));
        cloud.push_back(origin + d * static_cast<float>(far_m * 0.99));
      }
    }
  }
  return cloud;
}

}  // namespace densemap::test
