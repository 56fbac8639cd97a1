#pragma once

// What a query says of one cell, and of a ray: plain data for clients (no map internals).
#include <cstdint>

#include "densemap/geometry/point_cloud.hpp"

namespace densemap {

enum class CellState : std::uint8_t { kUnknown = 0, kFree = 1, kOccupied = 2 };

struct RayQueryResult {
  bool hit = false;
  Point3f hit_center = Point3f::Zero();  // centre of the first occupied cell
  float distance = 0.0F;                 // origin to that centre
};

}  // namespace densemap
