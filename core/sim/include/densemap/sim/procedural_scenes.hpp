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
};

/// Offices on both sides of a corridor (30 x 20 x 3 m): walls with doors, furniture, pillars.
[[nodiscard]] SimScene makeIndoorScene(unsigned seed);
/// A 120 m street: buildings on both sides, parked cars (boxes), poles, trees (cylinder trunk,
/// sphere crown), on a ground plane.
[[nodiscard]] SimScene makeOutdoorScene(unsigned seed);
/// "indoor", "outdoor", or a path to an OctoMap .bt/.ot file.
[[nodiscard]] Expected<SimScene> makeScene(const std::string& name_or_file, unsigned seed);

}  // namespace densemap
