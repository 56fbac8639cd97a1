#pragma once

#include <cstdint>
#include <string_view>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// How the rays of one scan combine in a cell (docs/architecture.md, exactness contract).
/// - kSet: OctoMap's rule. A cell is updated at most once per scan: occupied if any ray ends in
///   it, otherwise free if any ray crosses it.
/// - kPerRay: every ray counts (the dissertation's weighted super-ray model, Sec. 2.3.4): the
///   cell moves by n_occ * l_occ + n_free * l_free, summed in double, rounded to float once and
///   clamped once, so the order of rays does not matter.
enum class UpdateRule { kSet, kPerRay };

[[nodiscard]] std::string_view ruleName(UpdateRule rule);
/// "set" or "per_ray".
[[nodiscard]] Expected<UpdateRule> parseUpdateRule(std::string_view name);

/// The rays of one scan that reached a cell: how many crossed it and how many ended in it
/// (under kSet each is 0 or 1 and occupied excludes free).
struct CellHits {
  std::uint32_t free = 0;
  std::uint32_t occupied = 0;
};

}  // namespace densemap
