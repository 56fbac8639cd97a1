// The Mapper's distance field against OctoMap's dynamicEDT3D (DynamicEDTOctomap over the same
// final BALM map at 0.2 m, exported as .bt; same maximum distance, unknown as free): every
// cell of a box around the trajectory, away from the box's faces (dynamicEDT3D sees only the
// obstacles inside its box), holds the same squared distance in cells.
#include <dynamicEDT3D/dynamicEDTOctomap.h>
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cmath>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/mapper/mapper.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "exactness_harness.hpp"

namespace densemap {
namespace {

TEST(DistanceFieldDynamicEdt, EqualsDynamicEdt3dOnTheFinalBalmMap) {
  DENSEMAP_REQUIRE_DATA(balm, "balm-realworld");
  auto source = openScanSource(balm);
  ASSERT_TRUE(source) << source.error().message;
  const auto scans = test::loadWorldScans(**source, 0, 80);
  ASSERT_EQ(scans.size(), 80U);
  constexpr double kRes = 0.2;
  constexpr float kMaxDistance = 2.0F;
  MapperOptions m;
  m.resolution_m = kRes;
  m.threads = 2;
  m.distance_field = true;
  m.max_distance_m = kMaxDistance;
  auto mapper = Mapper::create(m);
  ASSERT_TRUE(mapper);
  Point3f lo = scans[0].origin, hi = scans[0].origin;
  for (const auto& s : scans) {
    ASSERT_TRUE(mapper->insertPointCloud(s.points, s.origin));
    lo = lo.cwiseMin(s.origin);
    hi = hi.cwiseMax(s.origin);
  }
  test::TempDir dir;
  const std::string bt = (dir.path() / "balm.bt").string();
  ASSERT_TRUE(mapper->save(bt));
  octomap::OcTree tree(bt);
  ASSERT_EQ(tree.getResolution(), kRes);

  // dynamicEDT3D keeps a dense array over its box: the trajectory's box grown by 8 m (3 m in z).
  const Point3f grow(8.0F, 8.0F, 3.0F);
  const Point3f box_lo = lo - grow, box_hi = hi + grow;
  DynamicEDTOctomap edt(kMaxDistance, &tree, octomap::point3d(box_lo.x(), box_lo.y(), box_lo.z()),
                        octomap::point3d(box_hi.x(), box_hi.y(), box_hi.z()), false);
  edt.update();

  // The cells at least the maximum distance (and a cell) inside the box.
  const VoxelGrid grid(kRes);
  const Point3f inset = Point3f::Constant(kMaxDistance + 2 * static_cast<float>(kRes));
  const VoxelKey klo = *grid.pointToKey(box_lo + inset), khi = *grid.pointToKey(box_hi - inset);
  std::vector<float> xyz;
  for (int z = klo.z; z <= khi.z; ++z) {
    for (int y = klo.y; y <= khi.y; ++y) {
      for (int x = klo.x; x <= khi.x; ++x) {
        const Point3f c =
            grid.keyToPoint(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                     static_cast<std::uint16_t>(z)});
        xyz.insert(xyz.end(), {c.x(), c.y(), c.z()});
      }
    }
  }
  auto ours = mapper->distance(xyz, {.nearest = false});
  ASSERT_TRUE(ours) << ours.error().message;
  // dynamicEDT3D keeps distances a cell beyond the maximum (its squared maximum is 11^2 here):
  // beyond ours (10 cells) both say "farther than the maximum".
  const int their_max = edt.getSquaredMaxDistCells();
  const int our_max = static_cast<int>(std::lround(std::pow(kMaxDistance / kRes, 2)));
  ASSERT_GE(their_max, our_max);
  std::size_t finite = 0, differ = 0;
  for (std::size_t i = 0; i < xyz.size() / 3; ++i) {
    const octomap::point3d p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    const int theirs = edt.getSquaredDistanceInCells(p);
    ASSERT_NE(theirs, DynamicEDTOctomap::distanceInCellsValue_Error);
    const bool their_far = theirs > our_max;
    float want = kMaxDistance;
    if (!their_far) {
      want = static_cast<float>(std::sqrt(static_cast<double>(theirs)) * kRes);
      ++finite;
    }
    // (A cell exactly at the maximum reads the maximum either way.)
    if (ours->distances[i] != want && ++differ <= 5) {
      ADD_FAILURE() << "cell at " << p << ": ours " << ours->distances[i] << " m, dynamicEDT3D "
                    << theirs << " cells^2";
    }
  }
  EXPECT_EQ(differ, 0U) << "of " << xyz.size() / 3 << " cells";
  EXPECT_GT(finite, 100000U);
}

}  // namespace
}  // namespace densemap
