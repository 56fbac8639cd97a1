#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "densemap/geometry/chunk_runner.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/planner/distance_field.hpp"
#include "densemap/planner/planner_types.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

/// The one rule for a distance request from outside: coordinates x y z per point, at most
/// `max_points` points, every coordinate finite and inside the map's addressable range.
[[nodiscard]] Expected<std::size_t> checkDistancePoints(const VoxelGrid& grid,
                                                        std::span<const float> xyz,
                                                        std::size_t max_points);

/// Distances from the points `xyz` to the nearest obstacle of `view`, whose occupied cells
/// `field` was last updated from (the same version). Chunks of points run on `runner`.
[[nodiscard]] Expected<DistanceQueryResult> queryDistances(
    const DistanceField& field, const MapView& view, std::span<const float> xyz,
    const DistanceQueryOptions& options, std::size_t max_points, const ChunkRunner& runner);

/// A box of the field as a dense array (nvblox's EsdfAndGradients): the distance (metres) of
/// every cell of the key box, x fastest, then y, then z.
struct DistanceBox {
  VoxelKey min{}, max{};
  std::array<std::uint32_t, 3> size{};
  std::vector<float> distances;
};

/// The cells of the box [min, max] (metres); refused past `max_cells`.
[[nodiscard]] Expected<DistanceBox> exportDistanceBox(const DistanceField& field,
                                                      const MapView& view, const Point3f& min,
                                                      const Point3f& max, bool unknown_as_occupied,
                                                      std::size_t max_cells);

}  // namespace densemap
