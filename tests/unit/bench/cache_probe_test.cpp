#include "cache_probe.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <thread>

namespace densemap::bench {
namespace {

// The probe measures memory, not the loop: a chase that leaves the caches (256 MiB) costs
// several times a step of one that stays in the first-level cache (16 KiB) on the same vCPU.
TEST(CacheProbe, AChaseBeyondTheCachesIsSlowerThanOneWithinThem) {
  const auto small = chaseNsPerStep(16 << 10, 0, 2'000'000);
  const auto large = chaseNsPerStep(std::size_t{256} << 20, 0, 1'000'000);
  ASSERT_TRUE(small && large);
  EXPECT_TRUE(std::isfinite(*small) && *small > 0.0) << *small;
  EXPECT_GT(*large, 3.0 * *small) << "16 KiB: " << *small << " ns, 256 MiB: " << *large << " ns";
}

TEST(CacheProbe, SaysWhenItCannotRunAndFormatsEachVcpu) {
  EXPECT_FALSE(chaseNsPerStep(64, 0, 10));            // one line: no cycle to chase
  EXPECT_FALSE(chaseNsPerStep(1 << 20, 100000, 10));  // no such vCPU to bind to
  const std::vector<double> ns = probeCaches(1 << 20, 1, 1000);
  ASSERT_EQ(ns.size(), 1U);
  EXPECT_GT(ns[0], 0.0);
  EXPECT_EQ(formatCacheProbe("before the lanes", 4 << 20, {17.34, -1.0, 104.0}),
            "cache probe before the lanes (4 MiB pointer chase, ns a step): vCPU 0 17.3, vCPU 1 "
            "-, vCPU 2 104.0");
}

}  // namespace
}  // namespace densemap::bench
