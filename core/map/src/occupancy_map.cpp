#include "densemap/map/occupancy_map.hpp"

namespace densemap {

std::string_view backendName(Backend backend) {
  switch (backend) {
    case Backend::kGrid:
      return "grid";
    case Backend::kOctree:
      return "octree";
  }
  return "?";
}

std::optional<float> OccupancyMap::logOddsAt(const Point3f& point_world) const {
  const auto key = grid().pointToKey(point_world);
  if (!key) return std::nullopt;
  return logOdds(*key);
}

}  // namespace densemap
