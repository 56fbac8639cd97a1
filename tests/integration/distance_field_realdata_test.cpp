// The Mapper's distance field against a brute-force reference on BALM's real scans (every 8th scan
// and the last): every cell within the maximum distance of an occupied cell holds the distance to
// the nearest one found by stamping every occupied cell's ball into a dense box, and every other
// cell of that box reports the maximum.
#include <gtest/gtest.h>

#include "densemap/mapper/mapper.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "distance_field_reference.hpp"
#include "exactness_harness.hpp"

namespace densemap {
namespace {

using test::expectEqualsBruteForce;

TEST(DistanceFieldExactness, EqualsBruteForceOnBalmRealScans) {
  DENSEMAP_REQUIRE_DATA(balm, "balm-realworld");
  auto source = openScanSource(balm);
  ASSERT_TRUE(source) << source.error().message;
  const auto scans = test::loadWorldScans(**source, 0, 80);
  ASSERT_EQ(scans.size(), 80U);
  MapperOptions m;
  m.resolution_m = 0.2;
  m.threads = 2;
  m.distance_field = true;
  m.max_distance_m = 2.0;
  auto mapper = Mapper::create(m);
  ASSERT_TRUE(mapper);
  for (std::size_t i = 0; i < scans.size(); ++i) {
    ASSERT_TRUE(mapper->insertPointCloud(scans[i].points, scans[i].origin));
    if (i % 8 == 0 || i + 1 == scans.size()) {
      expectEqualsBruteForce(*mapper, 2.0, "BALM after scan " + std::to_string(i));
    }
  }
}

}  // namespace
}  // namespace densemap
