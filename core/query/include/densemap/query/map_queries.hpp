#pragma once

#include <functional>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/query/cell_state.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

[[nodiscard]] inline CellState cellState(std::optional<float> log_odds) {
  if (!log_odds) return CellState::kUnknown;
  return SensorModel::isOccupied(*log_odds) ? CellState::kOccupied : CellState::kFree;
}

struct BoxQueryResult {
  std::size_t occupied = 0;
  std::size_t free = 0;
  std::size_t unknown = 0;
  std::vector<Point3f> occupied_centers;  // at most `max_centers`
};

/// Each query point's cell: its log-odds (NaN where unknown) and state (CellState as a byte).
struct PointQueryResult {
  std::vector<float> log_odds;
  std::vector<std::uint8_t> states;
};

/// The cells of the points `xyz` (x y z per point, metres; a non-finite or out-of-range point is
/// unknown). Errors for a length that is not a multiple of 3 or more than `max_points` points.
/// Chunks of points run on `runner` (the server passes tbbRunner(), in its query arena).
[[nodiscard]] Expected<PointQueryResult> queryPoints(const MapView& view,
                                                     std::span<const float> xyz,
                                                     std::size_t max_points = 10'000'000,
                                                     const ChunkRunner& runner = serialRunner());

/// The one rule for point coordinates from outside: x y z per point.
[[nodiscard]] Expected<void> checkPointCoordinates(std::size_t coordinates);

/// The one rule for a box from outside, without a map (the CLI checks before it sends): both
/// corners finite, min <= max on every axis.
[[nodiscard]] Expected<void> checkBox(const Point3f& min, const Point3f& max);

/// `direction` scaled to unit length, judged by its own scale (1e-7 along x is +x); none for a
/// zero or non-finite direction.
[[nodiscard]] std::optional<Point3f> unitDirection(const Point3f& direction);

/// The one rule for a ray from outside, without a map: finite, a direction of non-zero length
/// (unitDirection), a range in (0, 10 km].
[[nodiscard]] Expected<void> checkRay(const Point3f& origin, const Point3f& direction,
                                      float max_range);

/// The keys of the box [min, max] (metres): the one check of a box from the wire (bbox queries,
/// clear-bbox commands): errors for a non-finite corner, an inverted box, or a corner outside
/// the addressable range.
[[nodiscard]] Expected<std::pair<VoxelKey, VoxelKey>> boxKeys(const VoxelGrid& grid,
                                                              const Point3f& min,
                                                              const Point3f& max);

/// Counts the cells of the box [min, max] (metres) by state. Errors for an inverted box, a
/// non-finite corner, or a box of more than `max_cells` cells.
[[nodiscard]] Expected<BoxQueryResult> queryBox(const MapView& view, const Point3f& min,
                                                const Point3f& max, std::size_t max_cells,
                                                std::size_t max_centers);

/// Calls `f` with the key and log-odds of every known cell of the box [min, max] (metres; the
/// box's checks are boxKeys'), block by block. Costs O(blocks of the box) or O(blocks of the
/// map), whichever is fewer.
[[nodiscard]] Expected<void> forEachKnownInBox(
    const MapView& view, const Point3f& min, const Point3f& max,
    const std::function<void(const VoxelKey&, float)>& f);

/// Walks the ray (OctoMap's traversal) from `origin` along `direction` up to `max_range`; the
/// first occupied cell is the hit. Unknown cells are passed through.
[[nodiscard]] Expected<RayQueryResult> castRay(const MapView& view, const Point3f& origin,
                                               const Point3f& direction, float max_range);

}  // namespace densemap
