#include "densemap/map/map_factory.hpp"

#include <cmath>
#include <string>

#include "densemap/map/grid_map.hpp"
#include "densemap/map/octree_map.hpp"

namespace densemap {

Expected<Backend> parseBackend(std::string_view name) {
  if (name == "grid") return Backend::kGrid;
  if (name == "octree") return Backend::kOctree;
  return makeError("unknown map backend '" + std::string(name) + "' (expected grid or octree)");
}

Expected<std::unique_ptr<OccupancyMap>> makeMap(Backend backend, double resolution_m,
                                                const SensorModel& model) {
  // 1 mm .. 100 m: below, a 16-bit key covers under 66 m; above, a voxel is not a map.
  if (!std::isfinite(resolution_m) || resolution_m < 0.001 || resolution_m > 100.0) {
    return makeError("resolution must be between 0.001 and 100 m, got " +
                     std::to_string(resolution_m));
  }
  if (!model.isValid()) {
    return makeError("sensor model needs hit > 0.5 > miss and clamp_min < 0.5 < clamp_max");
  }
  switch (backend) {
    case Backend::kGrid:
      return std::make_unique<GridMap>(resolution_m, model);
    case Backend::kOctree:
      return std::make_unique<OctreeMap>(resolution_m, model);
  }
  return makeError("unknown backend");
}

}  // namespace densemap
