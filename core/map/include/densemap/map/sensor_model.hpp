#pragma once

#include <cmath>

namespace densemap {

/// The inverse sensor model as probabilities, the form users configure and OctoMap's setters
/// take. Defaults are OctoMap's and the dissertation's: hit 0.7 (l_occ ~0.85), miss 0.4
/// (l_free ~-0.4), clamping 0.1192 / 0.971 (l_min ~-2, l_max ~3.5).
struct SensorProbabilities {
  double hit = 0.7;
  double miss = 0.4;
  double clamp_min = 0.1192;
  double clamp_max = 0.971;
};

/// Log-odds sensor model with clamping, in OctoMap's float representation
/// (`OccupancyOcTreeBase::setProbHit` etc. store `(float) log(p / (1 - p))`). Immutable.
class SensorModel {
 public:
  SensorModel() : SensorModel(SensorProbabilities{}) {}
  explicit SensorModel(const SensorProbabilities& p)
      : probabilities_(p),
        hit_(logOdds(p.hit)),
        miss_(logOdds(p.miss)),
        clamp_min_(logOdds(p.clamp_min)),
        clamp_max_(logOdds(p.clamp_max)) {}

  [[nodiscard]] const SensorProbabilities& probabilities() const { return probabilities_; }
  [[nodiscard]] float hit() const { return hit_; }
  [[nodiscard]] float miss() const { return miss_; }
  [[nodiscard]] float clampMin() const { return clamp_min_; }
  [[nodiscard]] float clampMax() const { return clamp_max_; }
  /// hit > 0 > miss and clamp_min < 0 < clamp_max, all finite.
  [[nodiscard]] bool isValid() const {
    return std::isfinite(hit_) && std::isfinite(miss_) && std::isfinite(clamp_min_) &&
           std::isfinite(clamp_max_) && hit_ > 0.0F && miss_ < 0.0F && clamp_min_ < 0.0F &&
           clamp_max_ > 0.0F;
  }

  [[nodiscard]] static float logOdds(double probability) {
    return static_cast<float>(std::log(probability / (1.0 - probability)));
  }
  [[nodiscard]] static double probability(float log_odds) {
    return 1.0 - (1.0 / (1.0 + std::exp(static_cast<double>(log_odds))));
  }

  /// The value after one update, as `OccupancyOcTreeBase::updateNodeLogOdds` computes it:
  /// float addition, then clamping. An unknown cell starts at 0.
  [[nodiscard]] float update(float old_log_odds, bool occupied) const {
    return updateBy(old_log_odds, occupied ? hit_ : miss_);
  }
  /// `old + delta` in float, then clamped (`OccupancyOcTreeBase::updateNode(key, float)`).
  [[nodiscard]] float updateBy(float old_log_odds, float delta) const {
    float value = old_log_odds + delta;
    if (value < clamp_min_) value = clamp_min_;
    if (value > clamp_max_) value = clamp_max_;
    return value;
  }
  /// At the lower clamping bound: a free update cannot change the cell (the culling region's
  /// "fully free").
  [[nodiscard]] bool isFullyFree(float log_odds) const { return log_odds <= clamp_min_; }

  /// OctoMap's occupancy threshold (probability 0.5).
  [[nodiscard]] static bool isOccupied(float log_odds) { return log_odds > 0.0F; }

 private:
  SensorProbabilities probabilities_;
  float hit_;
  float miss_;
  float clamp_min_;
  float clamp_max_;
};

}  // namespace densemap
