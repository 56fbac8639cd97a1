#pragma once

#include <cstddef>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/raycast/ray_marking.hpp"

namespace densemap {

/// rayEndInto for `n` points: rays[i] as rayEndInto(grid, origin, points[i], max_range_m,
/// rays[i]) sets it, bit for bit. With AVX2 (hasFourLanes), eight points at a time: the squared
/// length in the same float operations, the range test, and the keys of the points clearly within
/// range in double lanes (coordToKey's product, bounds and floor); the points that are not (near
/// or beyond the range, not finite) are left to rayEndInto.
void rayEndsInto(const VoxelGrid& grid, const Point3f& origin, const Point3f* points, std::size_t n,
                 double max_range_m, RayEnd* rays);

}  // namespace densemap
