#pragma once

#include <memory>
#include <string_view>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// "grid" or "octree".
[[nodiscard]] Expected<Backend> parseBackend(std::string_view name);

/// A new, empty map. Errors for a resolution that is not finite and positive.
[[nodiscard]] Expected<std::unique_ptr<OccupancyMap>> makeMap(Backend backend, double resolution_m,
                                                              const SensorModel& model = {});

}  // namespace densemap
