#include "cpu_steal.hpp"

#include <gtest/gtest.h>

namespace densemap::bench {
namespace {

TEST(CpuSteal, ReadsTheCpuLinesTotalAndSteal) {
  const auto t = parseCpuLine("cpu  4705 356 584 3699 23 0 23 142 0 0");
  ASSERT_TRUE(t.has_value());
  EXPECT_EQ(t->total, 4705U + 356 + 584 + 3699 + 23 + 0 + 23 + 142);
  EXPECT_EQ(t->steal, 142U);
}

TEST(CpuSteal, RejectsOtherLinesAndShortOnes) {
  EXPECT_FALSE(parseCpuLine("cpu0 4705 356 584 3699 23 0 23 142 0 0").has_value());
  EXPECT_FALSE(parseCpuLine("cpu  4705 356 584 3699 23 0 23").has_value());
  EXPECT_FALSE(parseCpuLine("cpu  4705 356 584 x 23 0 23 142").has_value());
  EXPECT_FALSE(parseCpuLine("").has_value());
}

TEST(CpuSteal, MeterSumsIntervalsAndSaysWhenNothingWasRead) {
  StealMeter meter;
  EXPECT_LT(meter.share(), 0.0);
  meter.add(std::nullopt, CpuTimes{100, 10});
  EXPECT_LT(meter.share(), 0.0);
  meter.add(CpuTimes{100, 10}, CpuTimes{300, 60});  // 50 of 200 stolen
  meter.add(CpuTimes{500, 60}, CpuTimes{700, 60});  // none of 200
  meter.add(CpuTimes{700, 60}, CpuTimes{600, 70});  // a counter going back: left out
  EXPECT_DOUBLE_EQ(meter.share(), 50.0 / 400.0);
}

TEST(CpuSteal, ThisMachinesProcStatReads) {
  const auto t = readCpuTimes();
  if (!t) GTEST_SKIP() << "no /proc/stat here";
  EXPECT_GT(t->total, 0U);
  EXPECT_LE(t->steal, t->total);
}

}  // namespace
}  // namespace densemap::bench
