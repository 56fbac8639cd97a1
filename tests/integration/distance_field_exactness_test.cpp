// The Mapper's distance field against a brute-force reference after every simulated scan: every
// cell within the maximum distance of an occupied cell holds the distance to the nearest one found
// by stamping every occupied cell's ball into a dense box, and every other cell of that box
// reports the maximum.
#include <gtest/gtest.h>

#include "densemap/mapper/mapper.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "distance_field_reference.hpp"
#include "simulated_scans.hpp"

namespace densemap {
namespace {

using test::expectEqualsBruteForce;

TEST(DistanceFieldExactness, EqualsBruteForceAfterEverySimulatedScan) {
  for (const auto& [scene, sensor, res, max_distance] :
       {std::tuple{"indoor", "os128", 0.1, 0.8}, std::tuple{"outdoor", "hdl64", 0.2, 2.0}}) {
    test::TempDir dir;
    SequenceOptions o;
    o.scene = scene;
    o.sensor = sensor;
    o.columns = 512;
    o.scans = 5;
    o.seed = 9;
    o.ground_truth_resolution_m = 0;
    const auto scans = test::simulatedWorldScans(o, dir.path());
    ASSERT_EQ(scans.size(), 5U);
    MapperOptions m;
    m.resolution_m = res;
    m.max_range_m = 40.0;
    m.threads = 2;
    m.distance_field = true;
    m.max_distance_m = max_distance;
    // A keep radius that evicts: the field must follow cells that leave the map too.
    m.keep_radius_m = 25.0;
    auto mapper = Mapper::create(m);
    ASSERT_TRUE(mapper) << mapper.error().message;
    for (std::size_t i = 0; i < scans.size(); ++i) {
      ASSERT_TRUE(mapper->insertPointCloud(scans[i].points, scans[i].origin));
      expectEqualsBruteForce(*mapper, max_distance,
                             std::string(scene) + " after scan " + std::to_string(i));
    }
    // A cleared box and a cleared map: the field forgets with them.
    ASSERT_TRUE(mapper->clearBox(scans[0].origin - Point3f::Constant(5.0F),
                                 scans[0].origin + Point3f::Constant(5.0F)));
    expectEqualsBruteForce(*mapper, max_distance, std::string(scene) + " after clearBox");
  }
}

}  // namespace
}  // namespace densemap
