#include "densemap/raycast/integrator.hpp"

#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <limits>

#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

struct Case {
  double resolution;
  double max_range;  // < 0: unlimited
  int threads;
};

class RaycastMatchesOctomap : public ::testing::TestWithParam<Case> {};

TEST_P(RaycastMatchesOctomap, CellForCellAfterEveryScanOnBothBackends) {
  const Case c = GetParam();
  const double far = c.max_range > 0 ? c.max_range : 6.0;
  OctreeMap oracle(c.resolution, SensorModel{});
  GridMap grid(c.resolution, SensorModel{});
  grid.setRunner(tbbRunner());  // the grid's blocks in the arena's threads, as the engine's
  OctreeMap octree(c.resolution, SensorModel{});
  // One integrator per map: an integrator's region growth follows its own past scans.
  Integrator sut({.max_range_m = c.max_range}), sut_octree({.max_range_m = c.max_range});
  tbb::task_arena arena(c.threads);
  test::RandomRays origins(c.resolution, 1.0, 17);
  for (int scan = 0; scan < 8; ++scan) {
    // A moving origin, every other one on grid planes.
    const Point3f origin = origins.point(scan % 2 == 0 ? 1.0 : 0.0);
    const PointCloud cloud = test::adversarialScan(c.resolution, origin, 6000, far, 100 + scan);
    oracle.insertWithOctomap(cloud, origin, c.max_range);
    arena.execute([&] {
      const ScanStats a = sut.integrate(grid, cloud, origin);
      const ScanStats b = sut_octree.integrate(octree, cloud, origin);
      EXPECT_EQ(a.visits, b.visits);
      EXPECT_EQ(a.changed, b.changed);
      EXPECT_GT(a.updated, 0U);
    });
    const MapDiff dg = diffMaps(grid, oracle);
    const MapDiff dt = diffMaps(octree, oracle);
    ASSERT_EQ(dg.differing(), 0U) << "grid, scan " << scan << ": only-ours " << dg.only_in_a
                                  << " only-octomap " << dg.only_in_b << " values "
                                  << dg.value_mismatch;
    ASSERT_EQ(dt.differing(), 0U) << "octree, scan " << scan;
  }
  EXPECT_GT(oracle.knownCells(), 1000U);
}

INSTANTIATE_TEST_SUITE_P(ResolutionsRangesThreads, RaycastMatchesOctomap,
                         ::testing::Values(Case{0.1, -1.0, 1}, Case{0.1, 4.0, 2}, Case{0.2, 5.0, 1},
                                           Case{0.2, -1.0, 2}, Case{0.05, 2.5, 2},
                                           Case{0.4, 8.0, 2}, Case{0.15, 3.0, 1}),
                         [](const ::testing::TestParamInfo<Case>& param_info) {
                           const Case& c = param_info.param;
                           return "res" + std::to_string(static_cast<int>(c.resolution * 1000)) +
                                  "mm_range" +
                                  (c.max_range < 0
                                       ? std::string("inf")
                                       : std::to_string(static_cast<int>(c.max_range))) +
                                  "_threads" + std::to_string(c.threads);
                         });

TEST(Integrator, OneAndTwoThreadsGiveTheSameMapAndCounts) {
  GridMap one(0.1, SensorModel{}), two(0.1, SensorModel{});
  one.setRunner(tbbRunner());
  two.setRunner(tbbRunner());
  Integrator a({.max_range_m = 5.0}), b({.max_range_m = 5.0});
  tbb::task_arena arena1(1), arena2(2);
  for (int scan = 0; scan < 4; ++scan) {
    const Point3f origin(0.3F * scan, 0.1F, 0.05F);
    const PointCloud cloud = test::adversarialScan(0.1, origin, 20000, 5.0, scan);
    ScanStats sa, sb;
    arena1.execute([&] { sa = a.integrate(one, cloud, origin); });
    arena2.execute([&] { sb = b.integrate(two, cloud, origin); });
    EXPECT_EQ(sa.visits, sb.visits);
    EXPECT_EQ(sa.updated, sb.updated);
    EXPECT_EQ(sa.changed, sb.changed);
  }
  EXPECT_EQ(diffMaps(one, two).differing(), 0U);
}

TEST(Integrator, DenseMarksAndTheHashGiveTheSameMap) {
  // The same culling region for both (the region grows by the scan's marks only with dense
  // marks: growing, the default, visits fewer voxels for the same map).
  GridMap dense(0.1, SensorModel{}), hashed(0.1, SensorModel{}), grown(0.1, SensorModel{});
  Integrator a({.max_range_m = 5.0, .grow_strides = {}}),
      b({.max_range_m = 5.0, .dense_marks_max_blocks = 0}), c({.max_range_m = 5.0});
  for (int scan = 0; scan < 4; ++scan) {
    const Point3f origin(0.25F * scan, -0.1F, 0.2F);
    const PointCloud cloud = test::adversarialScan(0.1, origin, 8000, 5.0, 40 + scan);
    const ScanStats sa = a.integrate(dense, cloud, origin);
    const ScanStats sb = b.integrate(hashed, cloud, origin);
    const ScanStats sc = c.integrate(grown, cloud, origin);
    EXPECT_EQ(sa.visits, sb.visits);
    EXPECT_EQ(sa.changed, sb.changed);
    EXPECT_EQ(sc.changed, sb.changed);
  }
  EXPECT_EQ(diffMaps(dense, hashed).differing(), 0U);
  EXPECT_EQ(diffMaps(grown, hashed).differing(), 0U);
}

TEST(Integrator, CullingWithAndWithoutTheSharedBrickFrameGivesTheRaycastMap) {
  // Default: the region's bricks share the dense marks' frame. A small culling box does not
  // (its bricks would outgrow it): the region is tested on its own, inside a shrunken box.
  GridMap plain(0.1, SensorModel{}), shared(0.1, SensorModel{}), own(0.1, SensorModel{});
  Integrator r({.method = IntegrationMethod::kRaycast, .max_range_m = 5.0});
  Integrator a({.method = IntegrationMethod::kCulling, .max_range_m = 5.0});
  Integrator b(
      {.method = IntegrationMethod::kCulling, .max_range_m = 5.0, .culling_max_voxels = 20000});
  std::size_t culled_a = 0, culled_b = 0;
  for (int scan = 0; scan < 9; ++scan) {
    const Point3f origin(0.05F, -0.05F, 0.05F);  // dwell, so voxels saturate and culling starts
    PointCloud cloud = test::adversarialScan(0.1, origin, 6000, 5.0, 70 + scan);
    const VoxelGrid grid(0.1);
    std::erase_if(cloud,
                  [&](const Point3f& p) { return grid.pointToKey(p) == grid.pointToKey(origin); });
    r.integrate(plain, cloud, origin);
    culled_a += a.integrate(shared, cloud, origin).culled;
    culled_b += b.integrate(own, cloud, origin).culled;
    ASSERT_EQ(diffMaps(shared, plain).differing(), 0U) << "scan " << scan;
    ASSERT_EQ(diffMaps(own, plain).differing(), 0U) << "scan " << scan;
  }
  EXPECT_GT(culled_a, 0U);
  EXPECT_GT(culled_b, 0U);
}

TEST(Integrator, GrowingTheRegionByTheScansMarksGivesTheRaycastMapWithFewerVisits) {
  // The region grown between levels of rays (grow_strides) against the region from the map
  // only: the same map, and fewer voxels visited; it culls already in the first scans, where
  // no voxel is fully free yet, and after the sensor moves. Under kPerRay it is not grown.
  for (const UpdateRule rule : {UpdateRule::kSet, UpdateRule::kPerRay}) {
    GridMap plain(0.1, SensorModel{}), grown(0.1, SensorModel{}), map_only(0.1, SensorModel{});
    Integrator r({.method = IntegrationMethod::kRaycast, .rule = rule, .max_range_m = 5.0});
    Integrator g({.method = IntegrationMethod::kSuperRayCulling,
                  .rule = rule,
                  .max_range_m = 5.0,
                  .superray_min_points = 4,
                  .grow_strides = {16, 4},
                  .grow_min_share = 0.0});  // every scan grows
    Integrator m({.method = IntegrationMethod::kSuperRayCulling,
                  .rule = rule,
                  .max_range_m = 5.0,
                  .superray_min_points = 4,
                  .grow_strides = {}});
    std::size_t visits_grown = 0, visits_map_only = 0, culled_first = 0;
    const VoxelGrid grid(0.1);
    for (int scan = 0; scan < 10; ++scan) {
      const Point3f origin = scan < 6 ? Point3f(0.05F, -0.05F, 0.05F) : Point3f(0.43F, 0.21F, 0.0F);
      PointCloud cloud = test::adversarialScan(0.1, origin, 6000, 5.0, 170 + scan);
      std::erase_if(
          cloud, [&](const Point3f& p) { return grid.pointToKey(p) == grid.pointToKey(origin); });
      r.integrate(plain, cloud, origin);
      const ScanStats sg = g.integrate(grown, cloud, origin);
      const ScanStats sm = m.integrate(map_only, cloud, origin);
      if (scan == 0) culled_first = sg.culled;
      visits_grown += sg.visits;
      visits_map_only += sm.visits;
      ASSERT_EQ(diffMaps(grown, plain).differing(), 0U) << "scan " << scan;
      ASSERT_EQ(diffMaps(map_only, plain).differing(), 0U) << "scan " << scan;
      if (rule == UpdateRule::kPerRay) {
        EXPECT_EQ(sg.visits, sm.visits) << "scan " << scan;
      }
    }
    if (rule == UpdateRule::kSet) {
      EXPECT_GT(culled_first, 0U);
      EXPECT_LT(visits_grown, visits_map_only * 9 / 10);
    }
  }
}

TEST(Integrator, GrowsOnlyOnProbeScansWhileGrowingCullsTooLittle) {
  // A share no scan reaches: the first scan grows (nothing measured yet), then every third.
  GridMap grown(0.1, SensorModel{}), map_only(0.1, SensorModel{});
  Integrator g({.method = IntegrationMethod::kCulling,
                .max_range_m = 5.0,
                .grow_strides = {8},
                .grow_min_share = 1.5,
                .grow_probe_every = 3});
  Integrator m({.method = IntegrationMethod::kCulling, .max_range_m = 5.0, .grow_strides = {}});
  const VoxelGrid grid(0.1);
  for (int scan = 0; scan < 8; ++scan) {
    const Point3f origin(0.05F, -0.05F, 0.05F);
    PointCloud cloud = test::adversarialScan(0.1, origin, 4000, 5.0, 190 + scan);
    std::erase_if(cloud,
                  [&](const Point3f& p) { return grid.pointToKey(p) == grid.pointToKey(origin); });
    const ScanStats sg = g.integrate(grown, cloud, origin);
    const ScanStats sm = m.integrate(map_only, cloud, origin);
    const bool probe = scan % 3 == 0;
    if (probe) {
      EXPECT_LT(sg.visits, sm.visits) << "scan " << scan;
    } else {
      EXPECT_EQ(sg.visits, sm.visits) << "scan " << scan;
    }
    ASSERT_EQ(diffMaps(grown, map_only).differing(), 0U) << "scan " << scan;
  }
}

TEST(Integrator, AnyGrowStrideMarksEveryRayOnce) {
  // Strides of every size, up to SIZE_MAX (a level's ray count must not wrap): the raycast map.
  const VoxelGrid grid(0.1);
  const Point3f origin(0.05F, -0.05F, 0.05F);
  for (const std::size_t stride :
       {std::size_t{2}, std::size_t{4097}, std::numeric_limits<std::size_t>::max()}) {
    GridMap plain(0.1, SensorModel{}), grown(0.1, SensorModel{});
    Integrator r({.method = IntegrationMethod::kRaycast, .max_range_m = 5.0});
    Integrator g({.method = IntegrationMethod::kCulling,
                  .max_range_m = 5.0,
                  .grow_strides = {stride},
                  .grow_min_share = 0.0});
    for (int scan = 0; scan < 2; ++scan) {
      PointCloud cloud = test::adversarialScan(0.1, origin, 3000, 5.0, 210 + scan);
      std::erase_if(
          cloud, [&](const Point3f& p) { return grid.pointToKey(p) == grid.pointToKey(origin); });
      r.integrate(plain, cloud, origin);
      g.integrate(grown, cloud, origin);
      ASSERT_EQ(diffMaps(grown, plain).differing(), 0U) << "stride " << stride << " scan " << scan;
    }
  }
}

TEST(Integrator, NonFinitePointsAreIgnoredNotCrashing) {
  GridMap map(0.1, SensorModel{});
  Integrator sut({.max_range_m = 10.0});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  const PointCloud cloud{{nan, 0, 0}, {inf, 1, 1}, {1, -inf, 0}, {1, 0, 0}};
  const ScanStats s = sut.integrate(map, cloud, Point3f(0, 0, 0));
  EXPECT_EQ(s.points, 4U);
  EXPECT_EQ(map.knownCells(), 10U);  // 9 free cells to x=0.9 and the occupied end cell
}

}  // namespace
}  // namespace densemap
