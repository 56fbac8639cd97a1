// densemap::Mapper equals OctoMap's insertPointCloud cell for cell after every scan, on the
// exactness harness's simulated sequences, on both backends and under every integration
// method: the in-process API reaches the same engine as the server.
#include <gtest/gtest.h>

#include "densemap/mapper/mapper.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "simulated_scans.hpp"

namespace densemap {
namespace {

/// Every cell of `mapper` holds OctoMap's value, and both know as many cells.
void expectEqualsOctomap(const Mapper& mapper, const OctreeMap& oracle, const std::string& what) {
  ASSERT_EQ(mapper.knownCells(), oracle.knownCells()) << what;
  std::size_t differ = 0;
  mapper.forEachCell(CellFilter::kKnown, [&](const Point3f& centre, float v) {
    const auto key = oracle.grid().pointToKey(centre);
    const auto theirs = key ? oracle.logOdds(*key) : std::nullopt;
    if (!theirs || *theirs != v) ++differ;
  });
  EXPECT_EQ(differ, 0U) << what;
}

struct Case {
  std::string scene, sensor;
  int columns;
  double resolution, max_range;
};

class MapperEqualsOctomap : public ::testing::TestWithParam<Case> {};

TEST_P(MapperEqualsOctomap, AfterEveryScanOnBothBackendsAndEveryMethod) {
  const Case c = GetParam();
  test::TempDir dir;
  SequenceOptions o;
  o.scene = c.scene;
  o.sensor = c.sensor;
  o.columns = c.columns;
  o.scans = 5;
  o.seed = 7;
  o.ground_truth_resolution_m = 0;
  const auto scans = test::simulatedWorldScans(o, dir.path());
  ASSERT_EQ(scans.size(), 5U);
  OctreeMap oracle(c.resolution, SensorModel{});
  std::vector<std::pair<std::string, Mapper>> mappers;
  for (const std::string backend : {"grid", "octree"}) {
    for (const std::string method : {"raycast", "superray+culling", "raycast/versioned"}) {
      MapperOptions m;
      m.versioned_reads = method == "raycast/versioned";
      m.resolution_m = c.resolution;
      m.max_range_m = c.max_range;
      m.backend = backend;
      m.integration = method == "raycast/versioned" ? "raycast" : method;
      m.threads = 2;
      auto mapper = Mapper::create(m);
      ASSERT_TRUE(mapper) << mapper.error().message;
      mappers.emplace_back(backend + "/" + method, std::move(*mapper));
    }
  }
  for (std::size_t i = 0; i < scans.size(); ++i) {
    oracle.insertWithOctomap(scans[i].points, scans[i].origin, c.max_range);
    for (auto& [name, mapper] : mappers) {
      auto r = mapper.insertPointCloud(scans[i].points, scans[i].origin);
      ASSERT_TRUE(r) << r.error().message;
      EXPECT_EQ(r->version, i + 1);
      expectEqualsOctomap(mapper, oracle, name + " after scan " + std::to_string(i));
    }
  }
  EXPECT_GT(oracle.knownCells(), 1000U);
}

INSTANTIATE_TEST_SUITE_P(Sequences, MapperEqualsOctomap,
                         ::testing::Values(Case{"indoor", "os128", 512, 0.1, -1.0},
                                           Case{"outdoor", "hdl64", 1024, 0.2, 40.0}),
                         [](const ::testing::TestParamInfo<Case>& param_info) {
                           return param_info.param.scene + "_" + param_info.param.sensor;
                         });

}  // namespace
}  // namespace densemap
