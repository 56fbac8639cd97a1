#pragma once

#include <memory>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/sim/scene.hpp"

namespace densemap {

/// A scene with the path a sensor follows through it.
struct SimScene {
  std::string name;
  std::unique_ptr<Scene> scene;
  std::vector<Eigen::Vector3d> waypoints;  // sensor positions (world), followed in order
  /// The sensor stands at each waypoint in turn (scans shared out evenly, turning in place)
  /// instead of driving along the path.
  bool stations = false;
};

/// Offices on both sides of a corridor (30 x 20 x 3 m): walls with doors, furniture, pillars.
[[nodiscard]] SimScene makeIndoorScene(unsigned seed);
/// A street (120 m unless told): buildings on both sides, parked cars (boxes), poles, trees
/// (cylinder trunk, sphere crown), on a ground plane; the sensor drives its length.
[[nodiscard]] SimScene makeOutdoorScene(unsigned seed, double length_m = 120.0);
/// The AKIMap paper's "structured" benchmark (dissertation Sec. 3.4.1): rooms in 10 x 7 x 2 m —
/// outer and inner walls with doorways, an L-shaped wall, tables and pillars — seen from 4
/// stations.
[[nodiscard]] SimScene makeStructuredScene(unsigned seed);
/// Its "unstructured" counterpart: 10 x 7 x 2 m of irregular objects (rocks as spheres and
/// stacked boxes, trunks and bushes, slanted clutter) on a floor, seen from 4 stations.
[[nodiscard]] SimScene makeUnstructuredScene(unsigned seed);
/// "indoor", "outdoor", "street:LENGTH_M" (the outdoor street, LENGTH_M long: long drives),
/// "structured", "unstructured", or a path to an OctoMap .bt/.ot file.
[[nodiscard]] Expected<SimScene> makeScene(const std::string& name_or_file, unsigned seed);

}  // namespace densemap
