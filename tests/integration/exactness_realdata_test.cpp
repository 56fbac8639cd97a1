// The raycast integrator equals OctoMap cell for cell on real data from ../shared/data
// (skipped with a message where the data is absent).
#include <gtest/gtest.h>

#include "densemap/test_support/data_dir.hpp"
#include "exactness_harness.hpp"

namespace densemap {
namespace {

void checkDataset(const std::filesystem::path& path, std::size_t first, std::size_t count,
                  double max_range, std::size_t check_every) {
  auto source = openScanSource(path);
  ASSERT_TRUE(source) << source.error().message;
  const auto scans = test::loadWorldScans(**source, first, count);
  for (const double resolution : {0.1, 0.2}) {
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    test::expectRaycastEqualsOctomap(scans, resolution, max_range, check_every);
  }
}

TEST(RealData, BalmScans20To39) {
  DENSEMAP_REQUIRE_DATA(dir, "balm-realworld");
  checkDataset(dir, 0, 20, 30.0, 5);
}

TEST(RealData, La3dmStructured) {
  DENSEMAP_REQUIRE_DATA(dir, "la3dm/sim_structured");
  checkDataset(dir, 0, 12, 8.0, 1);
}

TEST(RealData, La3dmUnstructured) {
  DENSEMAP_REQUIRE_DATA(dir, "la3dm/sim_unstructured");
  checkDataset(dir, 0, 12, 8.0, 1);
}

TEST(RealData, AkimapSampleWorldClouds) {
  DENSEMAP_REQUIRE_DATA(dir, "akimap-sample");
  checkDataset(dir, 0, 73, -1.0, 10);
}

TEST(RealData, AkimapSampleGraphMatchesItsWorldClouds) {
  DENSEMAP_REQUIRE_DATA(graph, "akimap-sample/akimap_sample.graph");
  checkDataset(graph, 0, 20, -1.0, 5);
}

TEST(RealData, OctomapScanDat) {
  DENSEMAP_REQUIRE_DATA(file, "octomap/scan.dat.bz2");
  checkDataset(file, 0, 1, -1.0, 1);
}

TEST(RealData, OctomapSphericalScanGraph) {
  DENSEMAP_REQUIRE_DATA(file, "octomap/spherical_scan.graph");
  checkDataset(file, 0, 10, 20.0, 1);
}

}  // namespace
}  // namespace densemap
