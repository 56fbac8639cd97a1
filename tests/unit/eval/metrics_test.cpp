#include <gtest/gtest.h>

#include <vector>

#include "densemap/eval/metrics.hpp"

namespace densemap::eval {
namespace {

TEST(Metrics, PerfectSeparationHasAucOneAndKnownMse) {
  const std::vector<Prediction> p = {{0.9, true}, {0.8, true}, {0.2, false}, {0.1, false}};
  const Metrics m = evaluate(p);
  EXPECT_DOUBLE_EQ(m.auc, 1.0);
  EXPECT_NEAR(m.mse, (0.01 + 0.04 + 0.04 + 0.01) / 4, 1e-12);
  EXPECT_DOUBLE_EQ(m.acc_occupied, 1.0);
  EXPECT_DOUBLE_EQ(m.acc_free, 1.0);
  EXPECT_DOUBLE_EQ(m.acc_occupied_band, 1.0);  // 0.9 and 0.8 > 0.7
  EXPECT_DOUBLE_EQ(m.acc_free_band, 1.0);
}

TEST(Metrics, TiesAndInversionsCountAsMannWhitney) {
  // Pairs (occ, free): (0.6,0.6) tie = 0.5, (0.6,0.4) win, (0.3,0.6) loss, (0.3,0.4) loss.
  const std::vector<Prediction> p = {{0.6, true}, {0.3, true}, {0.6, false}, {0.4, false}};
  const Metrics m = evaluate(p);
  EXPECT_DOUBLE_EQ(m.auc, 1.5 / 4.0);
  EXPECT_DOUBLE_EQ(m.acc_occupied, 0.5);
  EXPECT_DOUBLE_EQ(m.acc_free, 0.5);
  EXPECT_DOUBLE_EQ(m.acc_occupied_band, 0.0);
}

TEST(Metrics, UnknownEverywhereIsChance) {
  const std::vector<Prediction> p = {{0.5, true}, {0.5, false}, {0.5, false}};
  const Metrics m = evaluate(p);
  EXPECT_DOUBLE_EQ(m.auc, 0.5);
  EXPECT_DOUBLE_EQ(m.mse, 0.25);
  EXPECT_DOUBLE_EQ(m.acc_occupied, 0.0);
}

TEST(Roc, CurveRunsFromOriginToOneOneAndItsAreaIsTheAuc) {
  const std::vector<Prediction> p = {{0.9, true}, {0.7, false}, {0.6, true}, {0.2, false}};
  const auto curve = rocCurve(p);
  ASSERT_GE(curve.size(), 2U);
  EXPECT_EQ(curve.front().false_positive_rate, 0.0);
  EXPECT_EQ(curve.back().false_positive_rate, 1.0);
  EXPECT_EQ(curve.back().true_positive_rate, 1.0);
  double area = 0.0;
  for (std::size_t i = 1; i < curve.size(); ++i) {
    area += (curve[i].false_positive_rate - curve[i - 1].false_positive_rate) * 0.5 *
            (curve[i].true_positive_rate + curve[i - 1].true_positive_rate);
  }
  EXPECT_NEAR(area, evaluate(p).auc, 1e-12);
}

TEST(Metrics, ReliabilityBinsCalibrationErrorAndKnownShare) {
  // Bin [0.1, 0.2): 0.15 twice, one occupied (observed 0.5); bin [0.9, 1]: 0.95 and 1.0, both
  // occupied; the unknown point scores 0.5 in bin [0.5, 0.6).
  const std::vector<Prediction> p = {
      {0.15, true}, {0.15, false}, {0.95, true}, {1.0, true}, {0.5, false, false}};
  const Metrics m = evaluate(p);
  ASSERT_EQ(m.reliability.size(), 10U);
  EXPECT_EQ(m.reliability[1].count, 2U);
  EXPECT_DOUBLE_EQ(m.reliability[1].mean_predicted, 0.15);
  EXPECT_DOUBLE_EQ(m.reliability[1].observed, 0.5);
  EXPECT_EQ(m.reliability[9].count, 2U);  // 1.0 falls in the last bin
  EXPECT_DOUBLE_EQ(m.reliability[9].mean_predicted, 0.975);
  EXPECT_EQ(m.reliability[5].count, 1U);
  EXPECT_EQ(m.reliability[0].count, 0U);
  EXPECT_DOUBLE_EQ(m.reliability[3].lower, 0.3);
  EXPECT_NEAR(m.ece, (2 * 0.35 + 2 * 0.025 + 1 * 0.5) / 5.0, 1e-12);
  EXPECT_DOUBLE_EQ(m.coverage, 0.8);
}

}  // namespace
}  // namespace densemap::eval
