// One percentile definition (nearest rank) for the server's status, the load tool's
// report, the benchmarks and the CLI's replay summary.
#include "densemap/geometry/percentile.hpp"

#include <gtest/gtest.h>

#include <numeric>

namespace densemap {
namespace {

TEST(Percentile, NearestRankIsTheSmallestValueWithAtLeastQAtOrBelowIt) {
  std::vector<double> hundred(100);
  std::iota(hundred.begin(), hundred.end(), 1.0);  // 1 .. 100
  EXPECT_EQ(nearestRank(hundred, 0.5), 50.0);
  EXPECT_EQ(nearestRank(hundred, 0.99), 99.0);  // floor(q n) indexing gave 100 here
  EXPECT_EQ(nearestRank(hundred, 0.999), 100.0);
  EXPECT_EQ(nearestRank(hundred, 0.0), 1.0);
  EXPECT_EQ(nearestRank(hundred, 1.0), 100.0);
  EXPECT_EQ(percentile({3.0, 1.0, 2.0}, 0.5), 2.0);
  EXPECT_EQ(percentile({5.0}, 0.99), 5.0);
  EXPECT_EQ(percentile({}, 0.5), 0.0);
}

}  // namespace
}  // namespace densemap
