#include "densemap/raycast/ray_ends.hpp"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "densemap/traversal/ray_traversal.hpp"

namespace densemap {
namespace {

/// Points that put every branch of rayEndInto in a batch: clearly within range, at the range
/// to the last float, beyond it, on cell borders, at and past the addressable cube's faces,
/// not finite.
std::vector<Point3f> hardPoints(const VoxelGrid& grid, const Point3f& origin, double range,
                                std::uint32_t seed, std::size_t n) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1.0F, 1.0F);
  std::uniform_int_distribution<int> kind(0, 11);
  const float r = range > 0 ? static_cast<float>(range) : 40.0F;
  const auto res = static_cast<float>(grid.resolution());
  const auto edge = static_cast<float>(grid.halfExtent());
  std::vector<Point3f> points;
  for (std::size_t i = 0; i < n; ++i) {
    Point3f d(unit(rng), unit(rng), unit(rng));
    if (d.norm() == 0.0F) d = Point3f(1, 0, 0);
    d.normalize();
    Point3f p = origin + d * (r * 0.9F * std::abs(unit(rng)));
    switch (kind(rng)) {
      case 0:  // at the range, give or take a few floats
        p = origin + d * std::nextafter(r, kind(rng) < 6 ? 0.0F : 1e9F);
        break;
      case 1:  // beyond it
        p = origin + d * (r * (1.0F + std::abs(unit(rng))));
        break;
      case 2:  // on a cell border
        p = Point3f(std::round(p.x() / res) * res, std::round(p.y() / res) * res, p.z());
        break;
      case 3:  // at or past a face of the addressable cube
        p[static_cast<int>(i % 3)] =
            (unit(rng) < 0 ? -1.0F : 1.0F) * std::nextafter(edge, kind(rng) < 6 ? 0.0F : 1e9F);
        break;
      case 4:
        p[static_cast<int>(i % 3)] = std::numeric_limits<float>::quiet_NaN();
        break;
      case 5:
        p[static_cast<int>(i % 3)] = -std::numeric_limits<float>::infinity();
        break;
      case 6:  // at the origin
        p = origin;
        break;
      default:
        break;
    }
    points.push_back(p);
  }
  return points;
}

void expectSame(const RayEnd& a, const RayEnd& b, std::size_t i) {
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_EQ(std::bit_cast<std::uint32_t>(a.end[axis]), std::bit_cast<std::uint32_t>(b.end[axis]))
        << "point " << i << " axis " << axis;
  }
  EXPECT_EQ(a.key_valid, b.key_valid) << "point " << i;
  EXPECT_EQ(a.key.x, b.key.x) << "point " << i;
  EXPECT_EQ(a.key.y, b.key.y) << "point " << i;
  EXPECT_EQ(a.key.z, b.key.z) << "point " << i;
  EXPECT_EQ(a.occupied, b.occupied) << "point " << i;
  EXPECT_EQ(a.weight, b.weight) << "point " << i;
}

TEST(RayEnds, BatchIsRayEndIntoBitForBit) {
  if (!hasFourLanes()) GTEST_SKIP() << "no AVX2 here: rayEndsInto is rayEndInto, one by one";
  std::size_t clearly_within = 0, total = 0;
  for (const double res : {0.05, 0.1, 0.2, 1.0}) {
    const VoxelGrid grid(res);
    for (const double range : {-1.0, 0.0, 3.0, 30.0, 80.0}) {
      for (std::uint32_t seed = 1; seed <= 12; ++seed) {
        const Point3f origin = seed % 3 == 0 ? Point3f(0, 0, 0)
                               : seed % 3 == 1
                                   ? Point3f(0.37F * static_cast<float>(seed), -1.1F, 0.5F)
                                   : Point3f(static_cast<float>(res) * 7, -static_cast<float>(res),
                                             static_cast<float>(res) * 3);
        // A length that is not a multiple of eight: the tail goes one by one.
        const std::vector<Point3f> points = hardPoints(grid, origin, range, seed, 203);
        std::vector<RayEnd> batch(points.size()), one(points.size());
        // Garbage in the outputs: every member must be written.
        for (RayEnd& r : batch) r = {{1, 2, 3}, {9, 9, 9}, 7, true, false};
        rayEndsInto(grid, origin, points.data(), points.size(), range, batch.data());
        for (std::size_t i = 0; i < points.size(); ++i) {
          rayEndInto(grid, origin, points[i], range, one[i]);
          expectSame(batch[i], one[i], i);
          const Point3f d = points[i] - origin;
          clearly_within += range < 0 || d.squaredNorm() < 0.9F * range * range ? 1 : 0;
        }
        total += points.size();
      }
    }
  }
  // Both paths taken: the lanes' and rayEndInto's.
  EXPECT_GT(clearly_within, total / 4);
  EXPECT_LT(clearly_within, total - total / 10);
}

}  // namespace
}  // namespace densemap
