#pragma once

// How one scan's rays change a cell's log-odds under each update rule, as both backends apply it.
#include "densemap/map/sensor_model.hpp"
#include "densemap/traversal/update_rule.hpp"

namespace densemap {

/// The log-odds change of a cell under kPerRay, as both backends apply it.
[[nodiscard]] inline float perRayDelta(const SensorModel& model, const CellHits& hits) {
  return static_cast<float>(static_cast<double>(hits.occupied) * model.hit() +
                            static_cast<double>(hits.free) * model.miss());
}

/// A cell's value after one scan under `rule`; an unknown cell starts at 0.
[[nodiscard]] inline float updatedLogOdds(const SensorModel& model, UpdateRule rule,
                                          float old_log_odds, const CellHits& hits) {
  if (rule == UpdateRule::kSet) return model.update(old_log_odds, hits.occupied > 0);
  return model.updateBy(old_log_odds, perRayDelta(model, hits));
}

}  // namespace densemap
