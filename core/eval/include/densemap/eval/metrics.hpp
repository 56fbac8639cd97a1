#pragma once

#include <cstddef>
#include <span>
#include <vector>

namespace densemap::eval {

/// A map's occupancy probability at a test point, and the point's true label. Unknown cells are
/// scored as 0.5.
struct Prediction {
  double probability = 0.5;
  bool occupied = false;
  bool known = true;  // false: the map had no evidence there (scored as `probability`, 0.5)
};

/// One bin of a reliability diagram: the test points whose predicted probability falls in
/// [lower, upper), their mean prediction and the share of them that is occupied.
struct ReliabilityBin {
  double lower = 0.0, upper = 0.0;
  std::size_t count = 0;
  double mean_predicted = 0.0;
  double observed = 0.0;
};

/// Accuracy figures of the dissertation (Sec. 2.4.2, Table 3.2).
struct Metrics {
  std::size_t occupied = 0, free = 0;  // test points per label
  double auc = 0.0;                    // ROC AUC; ties count half
  double mse = 0.0;                    // mean (p - label)^2
  double acc_occupied = 0.0;           // p > 0.5 among occupied points
  double acc_free = 0.0;               // p < 0.5 among free points
  double acc_occupied_band = 0.0;      // p > 0.7 among occupied points (0.3/0.7 thresholds)
  double acc_free_band = 0.0;          // p < 0.3 among free points
  double coverage = 0.0;               // share of test points the map knows
  /// Calibration: 10 equal bins of predicted probability (the last includes 1), and the
  /// expected calibration error, sum over bins of count/N * |mean_predicted - observed|.
  std::vector<ReliabilityBin> reliability;
  double ece = 0.0;
};

/// Metrics of `predictions`; AUC is 0.5 when one label is absent.
[[nodiscard]] Metrics evaluate(std::span<const Prediction> predictions);

struct RocPoint {
  double threshold;
  double false_positive_rate;
  double true_positive_rate;
};
/// The ROC curve: one point per distinct probability (p >= threshold counts as occupied),
/// from (0, 0) to (1, 1).
[[nodiscard]] std::vector<RocPoint> rocCurve(std::span<const Prediction> predictions);

}  // namespace densemap::eval
