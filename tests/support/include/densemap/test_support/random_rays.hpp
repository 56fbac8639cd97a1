#pragma once

#include <random>

#include "densemap/geometry/point_cloud.hpp"

namespace densemap::test {

/// Kinds of rays that stress a voxel traversal's floating-point boundary handling.
enum class RayKind {
  kUniform,        // both ends uniform in a box around the origin (negative coordinates too)
  kOnFaces,        // end (and often origin) with one coordinate exactly on a grid plane
  kOnEdges,        // two coordinates on grid planes
  kOnCorners,      // all three on grid planes
  kAxisAligned,    // end differs from origin in one or two axes only
  kZeroLength,     // end == origin
  kOriginOnPlane,  // origin on a grid plane, end anywhere
  kShort,          // end within a voxel or two of the origin
};
inline constexpr RayKind kAllRayKinds[] = {
    RayKind::kUniform,     RayKind::kOnFaces,    RayKind::kOnEdges,       RayKind::kOnCorners,
    RayKind::kAxisAligned, RayKind::kZeroLength, RayKind::kOriginOnPlane, RayKind::kShort};

struct Ray {
  Point3f origin;
  Point3f end;
};

/// Seeded generator of rays of one kind on a grid of the given resolution, within +-extent_m.
class RandomRays {
 public:
  RandomRays(double resolution_m, double extent_m, unsigned seed)
      : resolution_m_(resolution_m), extent_m_(extent_m), rng_(seed) {}
  Ray next(RayKind kind);
  /// A point with each coordinate independently on a grid plane with probability p_plane.
  Point3f point(double p_plane);

 private:
  float coordinate(bool on_plane);
  double resolution_m_;
  double extent_m_;
  std::mt19937_64 rng_;
};

}  // namespace densemap::test

namespace densemap::test {

/// A scan built to hit floating-point corner cases: points on cell faces, edges and corners,
/// axis-parallel rays from the origin, many points in one cell, points beyond `far_m`, a point
/// at the origin; the rest uniform within `far_m`.
[[nodiscard]] PointCloud adversarialScan(double resolution_m, const Point3f& origin, int n,
                                         double far_m, unsigned seed);

}  // namespace densemap::test
