#include "densemap/eval/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace densemap::eval {
namespace {

std::vector<Prediction> sortedDescending(std::span<const Prediction> predictions) {
  std::vector<Prediction> sorted(predictions.begin(), predictions.end());
  std::sort(sorted.begin(), sorted.end(),
            [](const Prediction& a, const Prediction& b) { return a.probability > b.probability; });
  return sorted;
}

}  // namespace

Metrics evaluate(std::span<const Prediction> predictions) {
  Metrics m;
  double squared = 0.0;
  std::size_t occ_ok = 0, free_ok = 0, occ_band = 0, free_band = 0, known = 0;
  constexpr int kBins = 10;
  m.reliability.resize(kBins);
  for (int b = 0; b < kBins; ++b) {
    m.reliability[b].lower = static_cast<double>(b) / kBins;
    m.reliability[b].upper = static_cast<double>(b + 1) / kBins;
  }
  for (const Prediction& p : predictions) {
    const double label = p.occupied ? 1.0 : 0.0;
    squared += (p.probability - label) * (p.probability - label);
    known += p.known ? 1 : 0;
    ReliabilityBin& bin =
        m.reliability[std::clamp(static_cast<int>(p.probability * kBins), 0, kBins - 1)];
    ++bin.count;
    bin.mean_predicted += p.probability;
    bin.observed += label;
    if (p.occupied) {
      ++m.occupied;
      occ_ok += p.probability > 0.5 ? 1 : 0;
      occ_band += p.probability > 0.7 ? 1 : 0;
    } else {
      ++m.free;
      free_ok += p.probability < 0.5 ? 1 : 0;
      free_band += p.probability < 0.3 ? 1 : 0;
    }
  }
  const auto ratio = [](std::size_t a, std::size_t b) {
    return b == 0 ? 0.0 : static_cast<double>(a) / static_cast<double>(b);
  };
  m.mse = predictions.empty() ? 0.0 : squared / static_cast<double>(predictions.size());
  m.coverage = ratio(known, predictions.size());
  for (ReliabilityBin& bin : m.reliability) {
    if (bin.count == 0) continue;
    bin.mean_predicted /= static_cast<double>(bin.count);
    bin.observed /= static_cast<double>(bin.count);
    m.ece += static_cast<double>(bin.count) / static_cast<double>(predictions.size()) *
             std::abs(bin.mean_predicted - bin.observed);
  }
  m.acc_occupied = ratio(occ_ok, m.occupied);
  m.acc_free = ratio(free_ok, m.free);
  m.acc_occupied_band = ratio(occ_band, m.occupied);
  m.acc_free_band = ratio(free_band, m.free);
  if (m.occupied == 0 || m.free == 0) {
    m.auc = 0.5;
    return m;
  }
  // Mann-Whitney: P(p_occupied > p_free) + 0.5 P(equal), over groups of equal probability.
  const std::vector<Prediction> sorted = sortedDescending(predictions);
  double wins = 0.0;
  std::size_t occupied_above = 0;
  for (std::size_t i = 0; i < sorted.size();) {
    std::size_t j = i, occ = 0, fr = 0;
    while (j < sorted.size() && sorted[j].probability == sorted[i].probability) {
      (sorted[j].occupied ? occ : fr) += 1;
      ++j;
    }
    wins += static_cast<double>(fr) * (static_cast<double>(occupied_above) + 0.5 * occ);
    occupied_above += occ;
    i = j;
  }
  m.auc = wins / (static_cast<double>(m.occupied) * static_cast<double>(m.free));
  return m;
}

std::vector<RocPoint> rocCurve(std::span<const Prediction> predictions) {
  std::vector<RocPoint> curve = {{std::numeric_limits<double>::infinity(), 0.0, 0.0}};
  std::size_t positives = 0, negatives = 0;
  for (const Prediction& p : predictions) (p.occupied ? positives : negatives) += 1;
  const std::vector<Prediction> sorted = sortedDescending(predictions);
  std::size_t tp = 0, fp = 0;
  for (std::size_t i = 0; i < sorted.size();) {
    const double threshold = sorted[i].probability;
    while (i < sorted.size() && sorted[i].probability == threshold) {
      (sorted[i].occupied ? tp : fp) += 1;
      ++i;
    }
    curve.push_back({threshold, negatives == 0 ? 0.0 : static_cast<double>(fp) / negatives,
                     positives == 0 ? 0.0 : static_cast<double>(tp) / positives});
  }
  return curve;
}

}  // namespace densemap::eval
