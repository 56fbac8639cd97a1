#include <gtest/gtest.h>

#include <string>

#include "bench_report.hpp"

namespace densemap::bench {
namespace {

RunResult lane(const char* method, int threads, std::vector<double> openers,
               std::vector<double> rest) {
  RunResult r;
  r.method = method;
  r.backend = "grid";
  r.threads = threads;
  r.ms_opening_turn = std::move(openers);
  r.ms_within_turn = std::move(rest);
  return r;
}

// The turn table keeps the scans that open a lane's turn apart from the rest: a slow first
// scan after the other lanes ran shows as the openers' p50, not in the rest's.
TEST(TurnTable, SplitsTheOpenersP50FromTheRest) {
  const RunResult r = lane("raycast@t2", 2, {9.0, 9.4, 8.8}, {5.0, 5.6, 5.2, 5.4, 30.0});
  EXPECT_DOUBLE_EQ(r.openingTurnP50(), 9.0);
  EXPECT_DOUBLE_EQ(r.withinTurnP50(), 5.4);
  // Nearest rank (the one percentile): the p50 of two openers is the smaller.
  const std::string table = formatTurnTable({lane("raycast@t1", 1, {10.8, 10.2}, {10.0}), r});
  EXPECT_NE(table.find("raycast@t1       grid      1        2       10.2        1       10.0"),
            std::string::npos)
      << table;
  EXPECT_NE(table.find("raycast@t2       grid      2        3        9.0        5        5.4"),
            std::string::npos)
      << table;
}

TEST(TurnTable, IsEmptyWhenNoLaneHadASecondTurn) {
  EXPECT_EQ(formatTurnTable({lane("raycast", 2, {12.0}, {5.0, 6.0})}), "");
  const RunResult none = lane("raycast", 2, {}, {});
  EXPECT_EQ(none.withinTurnP50(), 0.0);
  EXPECT_EQ(none.openingTurnP50(), 0.0);
}

}  // namespace
}  // namespace densemap::bench
