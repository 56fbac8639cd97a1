#include "densemap/traversal/ray_traversal.hpp"

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cstdlib>
#include <string>
#include <vector>

#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

using test::RayKind;

struct OracleResult {
  bool ok;
  std::vector<VoxelKey> keys;
};

OracleResult octomapRay(const octomap::OcTree& tree, const Point3f& o, const Point3f& e) {
  octomap::KeyRay ray;
  const bool ok = tree.computeRayKeys(octomap::point3d(o.x(), o.y(), o.z()),
                                      octomap::point3d(e.x(), e.y(), e.z()), ray);
  OracleResult r{ok, {}};
  for (const auto& k : ray) r.keys.push_back({k[0], k[1], k[2]});
  return r;
}

void expectSameAsOctomap(double resolution, double extent, RayKind kind, int n, unsigned seed) {
  octomap::OcTree tree(resolution);
  const VoxelGrid sut(resolution);
  test::RandomRays rays(resolution, extent, seed);
  std::vector<VoxelKey> keys;
  int mismatches = 0;
  for (int i = 0; i < n; ++i) {
    const test::Ray r = rays.next(kind);
    const OracleResult expected = octomapRay(tree, r.origin, r.end);
    const bool ok = computeRayKeys(sut, r.origin, r.end, keys);
    if (ok != expected.ok || keys != expected.keys) {
      if (++mismatches <= 3) {
        ADD_FAILURE() << "ray " << i << " kind " << static_cast<int>(kind) << " res " << resolution
                      << " from " << r.origin.transpose() << " to " << r.end.transpose() << ": "
                      << keys.size() << " keys vs OctoMap's " << expected.keys.size();
      }
    }
  }
  EXPECT_EQ(mismatches, 0);
}

class RayTraversalMatchesOctomap : public ::testing::TestWithParam<double> {};

TEST_P(RayTraversalMatchesOctomap, OnEveryKindOfRay) {
  const double resolution = GetParam();
  unsigned seed = 1;
  for (const RayKind kind : test::kAllRayKinds) {
    // Extent in voxels kept moderate so a million rays stay fast; short kinds get more rays.
    const int n = (kind == RayKind::kShort || kind == RayKind::kZeroLength) ? 40000 : 25000;
    expectSameAsOctomap(resolution, 40.0 * resolution, kind, n, seed++);
  }
}

INSTANTIATE_TEST_SUITE_P(Resolutions, RayTraversalMatchesOctomap,
                         ::testing::Values(0.05, 0.1, 0.2, 0.4, 0.15, 0.3, 1.0 / 3.0));

TEST(RayTraversal, LongRaysMatchOctomap) {
  expectSameAsOctomap(0.1, 60.0, RayKind::kUniform, 20000, 99);
  expectSameAsOctomap(0.2, 100.0, RayKind::kOnFaces, 20000, 98);
}

// A ray of ~1e-23 m across a voxel border has a float
// length of 0; OctoMap's loop never ends on it (tDelta 0). It visits nothing, as a ray inside
// one voxel, forward and backward.
TEST(RayTraversal, ARayTooShortForAFloatLengthAcrossABorderVisitsNothing) {
  const VoxelGrid sut(0.1);
  const Point3f origin(1.2e-7F, 1.7e-38F, 1.7e-38F);
  const Point3f end(1.2e-7F, -4.9e-32F, -6.6e-24F);
  ASSERT_NE(sut.pointToKey(origin), sut.pointToKey(end));  // two voxels
  std::vector<VoxelKey> keys;
  EXPECT_TRUE(computeRayKeys(sut, origin, end, keys));
  EXPECT_TRUE(keys.empty());
  TraversalStart start;
  EXPECT_EQ(startTraversal(sut, origin, end, start), TraversalKind::kSameVoxel);
}

TEST(RayTraversal, OutOfRangeEndsVisitNothingAndFail) {
  const VoxelGrid sut(0.1);
  std::vector<VoxelKey> keys;
  const float beyond = static_cast<float>(sut.halfExtent() + 1.0);
  EXPECT_FALSE(computeRayKeys(sut, Point3f(0, 0, 0), Point3f(beyond, 0, 0), keys));
  EXPECT_TRUE(keys.empty());
  EXPECT_FALSE(computeRayKeys(sut, Point3f(-beyond, 0, 0), Point3f(0, 0, 0), keys));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(computeRayKeys(sut, Point3f(0, 0, 0), Point3f(nan, 0, 0), keys));
}

TEST(RayTraversal, ConsecutiveKeysAreFaceNeighboursAndEndIsExcluded) {
  const VoxelGrid sut(0.1);
  test::RandomRays rays(0.1, 5.0, 7);
  std::vector<VoxelKey> keys;
  for (int i = 0; i < 2000; ++i) {
    const test::Ray r = rays.next(RayKind::kUniform);
    ASSERT_TRUE(computeRayKeys(sut, r.origin, r.end, keys));
    if (keys.empty()) continue;
    EXPECT_EQ(keys.front(), *sut.pointToKey(r.origin));
    for (const VoxelKey& k : keys) EXPECT_NE(k, *sut.pointToKey(r.end));
    for (std::size_t j = 1; j < keys.size(); ++j) {
      int manhattan = 0;
      for (int a = 0; a < 3; ++a) manhattan += std::abs(int{keys[j][a]} - int{keys[j - 1][a]});
      ASSERT_EQ(manhattan, 1) << "ray " << i << " step " << j;
    }
  }
}

// DENSEMAP_LANES caps every kernel's lanes (CTest also runs this binary with 256 and with 0,
// so that the other tests here take the narrower paths): below 512 no AVX-512 path, below 256
// no AVX2 path.
TEST(LaneCap, FollowsDensemapLanes) {
  const char* value = std::getenv("DENSEMAP_LANES");
  const std::string set = value != nullptr ? value : "";
  const int want = set == "256" ? 256 : set == "0" ? 0 : 512;
  EXPECT_EQ(laneCap(), want);
  if (want < 512) {
    EXPECT_FALSE(hasWideLanes());
  }
  if (want < 256) {
    EXPECT_FALSE(hasFourLanes());
  }
}

}  // namespace
}  // namespace densemap
