#include "densemap/geometry/voxel_grid.hpp"

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

TEST(VoxelGrid, KeysMatchOctomapCoordToKeyChecked) {
  for (const double res : {0.05, 0.1, 0.2, 0.3}) {
    const octomap::OcTree tree(res);
    const VoxelGrid sut(res);
    test::RandomRays gen(res, 50.0, 3);
    for (int i = 0; i < 100000; ++i) {
      const Point3f p = gen.point(0.5);
      octomap::OcTreeKey expected;
      ASSERT_TRUE(tree.coordToKeyChecked(octomap::point3d(p.x(), p.y(), p.z()), expected));
      const auto key = sut.pointToKey(p);
      ASSERT_TRUE(key.has_value());
      EXPECT_EQ(key->x, expected[0]);
      EXPECT_EQ(key->y, expected[1]);
      EXPECT_EQ(key->z, expected[2]);
      const octomap::point3d c = tree.keyToCoord(expected);
      EXPECT_EQ(sut.keyToPoint(*key), Point3f(c.x(), c.y(), c.z()));
    }
  }
}

TEST(VoxelGrid, TheOriginIsTheLowerCornerOfKey32768) {
  const VoxelGrid sut(0.1);
  EXPECT_EQ(*sut.coordToKey(0.0), 32768);
  EXPECT_EQ(*sut.coordToKey(-1e-6), 32767);
  EXPECT_EQ(*sut.coordToKey(sut.halfExtent() - 0.01), 65535);
  EXPECT_FALSE(sut.coordToKey(sut.halfExtent()).has_value());
  EXPECT_FALSE(sut.coordToKey(-sut.halfExtent() - 0.01).has_value());
}

TEST(VoxelGrid, PackedKeysRoundTrip) {
  const VoxelKey k{1, 65535, 32768};
  EXPECT_EQ(VoxelKey::fromPacked(k.packed()), k);
}

TEST(RigidTransform, KittiRowsAndQuaternionAgree) {
  const Transform a =
      transformFromTranslationQuaternion({1, 2, 3}, std::cos(0.25), 0, 0, std::sin(0.25));
  double rows[12];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) rows[r * 4 + c] = a.matrix()(r, c);
  }
  const Transform b = transformFromRows(rows);
  const PointCloud pts{{1, 0, 0}, {0, 1, 0}};
  EXPECT_EQ(transformPoints(a, pts), transformPoints(b, pts));
  EXPECT_NEAR(transformPoints(a, pts)[0].y(), 2.0 + std::sin(0.5), 1e-6);
  EXPECT_EQ(sensorOrigin(a), Point3f(1, 2, 3));
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

TEST(PointCloud, RemoveNonFiniteKeepsOrderAndCounts) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  PointCloud sut{{1, 2, 3}, {nan, 0, 0}, {4, 5, 6}, {0, -inf, 0}, {7, 8, 9}};
  EXPECT_EQ(removeNonFinite(sut), 2U);
  EXPECT_EQ(sut, (PointCloud{{1, 2, 3}, {4, 5, 6}, {7, 8, 9}}));
}

}  // namespace
}  // namespace densemap
