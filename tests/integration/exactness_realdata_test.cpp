// Every integration method equals OctoMap cell for cell (rule "set") and the plain per-ray
// result (rule "per_ray") on real data from ../shared/data (skipped with a message where the
// data is absent).
#include <gtest/gtest.h>

#include "densemap/test_support/data_dir.hpp"
#include "exactness_harness.hpp"

namespace densemap {
namespace {

void checkDataset(const std::filesystem::path& path, std::size_t first, std::size_t count,
                  double max_range, std::size_t check_every,
                  std::initializer_list<double> resolutions = {0.1, 0.2},
                  const std::vector<test::MethodCase>& cases = test::standardCases(),
                  bool expect_savings = true) {
  auto source = openScanSource(path);
  ASSERT_TRUE(source) << source.error().message;
  const auto scans = test::loadWorldScans(**source, first, count);
  for (const double resolution : resolutions) {
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    test::expectMethodsAgree(scans, resolution, max_range, check_every, cases, expect_savings);
  }
}

// Few scans from far-apart poses (la3dm, the AKIMap sample, OctoMap's examples) leave no voxel
// with 20 returns and no saturated free space around the sensor: exactness only. Savings are
// asserted on BALM, the simulated sequences and the adversarial unit tests.
constexpr bool kNoSavingsExpected = false;

TEST(RealData, BalmAll80ScansAt20cm) {
  DENSEMAP_REQUIRE_DATA(dir, "balm-realworld");
  // Every method under both rules on the grid, the default on the octree (the octree's other
  // methods are covered on the shorter datasets below).
  checkDataset(dir, 0, 80, 30.0, 10, {0.2});
}

TEST(RealData, BalmScans20To39At10cm) {
  DENSEMAP_REQUIRE_DATA(dir, "balm-realworld");
  checkDataset(dir, 0, 20, 30.0, 5, {0.1});
}

TEST(RealData, La3dmStructured) {
  DENSEMAP_REQUIRE_DATA(dir, "la3dm/sim_structured");
  checkDataset(dir, 0, 12, 8.0, 1, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

TEST(RealData, La3dmUnstructured) {
  DENSEMAP_REQUIRE_DATA(dir, "la3dm/sim_unstructured");
  checkDataset(dir, 0, 12, 8.0, 1, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

TEST(RealData, AkimapSampleWorldClouds) {
  DENSEMAP_REQUIRE_DATA(dir, "akimap-sample");
  checkDataset(dir, 0, 73, -1.0, 10, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

TEST(RealData, AkimapSampleGraphMatchesItsWorldClouds) {
  DENSEMAP_REQUIRE_DATA(graph, "akimap-sample/akimap_sample.graph");
  DENSEMAP_REQUIRE_DATA(clouds, "akimap-sample");
  // Two independent stagings of the same data: sensor-frame points + pose in the .graph,
  // world-frame points in clouds_world/. The readers must agree to float precision.
  auto from_graph = openScanSource(graph);
  auto from_clouds = openScanSource(clouds);
  ASSERT_TRUE(from_graph && from_clouds);
  ASSERT_EQ((*from_graph)->size(), (*from_clouds)->size());
  for (std::size_t i = 0; i < (*from_graph)->size(); i += 9) {
    const Scan a = *(*from_graph)->load(i);
    const Scan b = *(*from_clouds)->load(i);
    ASSERT_EQ(a.points.size(), b.points.size());
    EXPECT_LT((a.originWorld() - b.originWorld()).norm(), 1e-4F);
    const PointCloud wa = a.pointsWorld();
    float worst = 0;
    for (std::size_t j = 0; j < wa.size(); ++j)
      worst = std::max(worst, (wa[j] - b.points[j]).norm());
    EXPECT_LT(worst, 1e-4F) << "cloud " << i;
  }
  checkDataset(graph, 0, 20, -1.0, 5, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

TEST(RealData, OctomapScanDat) {
  DENSEMAP_REQUIRE_DATA(file, "octomap/scan.dat.bz2");
  checkDataset(file, 0, 1, -1.0, 1, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

TEST(RealData, OctomapSphericalScanGraph) {
  DENSEMAP_REQUIRE_DATA(file, "octomap/spherical_scan.graph");
  checkDataset(file, 0, 10, 20.0, 1, {0.1, 0.2}, test::standardCases(), kNoSavingsExpected);
}

}  // namespace
}  // namespace densemap
