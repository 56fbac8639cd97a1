#pragma once

#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/planner/planner_types.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

/// What a request may ask of a swept-volume check; past these it is refused with the reason.
struct SweptVolumeLimits {
  std::size_t max_vertices = 100'000;
  std::size_t max_boxes = 100'000;
  double max_path_length_m = 10'000.0;
  double max_radius_m = 50.0;
  /// Cells the volume's pieces may cover (their bounding boxes, summed).
  double max_cells = 100'000'000.0;
};

/// The one rule for a path from outside: x y z per vertex, 1 .. max_vertices vertices, finite,
/// inside the map's range, radius finite in [0, max_radius_m], length within the limit.
/// Returns the path's length (metres).
[[nodiscard]] Expected<double> checkPathRequest(const VoxelGrid& grid, std::span<const float> xyz,
                                              double radius_m, const SweptVolumeLimits& limits);

/// The capsules of the polyline `xyz` (x y z per vertex) with radius `radius_m`: every cell
/// whose closed cube lies within radius_m of the path. Exact (a cell is counted if and only if
/// it is within the radius, up to a tolerance of 1e-6 cells that only adds cells: conservative).
[[nodiscard]] Expected<SweptVolumeResult> checkPath(const MapView& view, std::span<const float> xyz,
                                                    double radius_m,
                                                    const SweptVolumeLimits& limits = {});

/// Oriented boxes as flat floats (the wire's form): 10 per box, centre x y z, half extents
/// x y z, rotation x y z w.
inline constexpr std::size_t kBoxFloats = 10;
void appendBoxFloats(const OrientedBox& box, std::vector<float>& out);
/// The boxes of `floats`: a multiple of kBoxFloats, at most `max_boxes` boxes (checkBoxes
/// checks the values themselves).
[[nodiscard]] Expected<std::vector<OrientedBox>> boxesFromFloats(std::span<const float> floats,
                                                                 std::size_t max_boxes);

/// The boxes in order: every cell whose closed cube intersects a box (separating axes, exact
/// up to the same tolerance). The conflict's `index` is the box; arc_length is 0.
[[nodiscard]] Expected<SweptVolumeResult> checkBoxes(const MapView& view,
                                                     std::span<const OrientedBox> boxes,
                                                     const SweptVolumeLimits& limits = {});

/// The squared distance from the segment [a, b] to the closed box [lo, hi], and the smallest
/// s in [0, 1] at which a + s (b - a) is within sqrt(r2) of the box (none when no point is).
struct SegmentBoxContact {
  double min_d2 = 0.0;
  std::optional<double> first_s;
};
[[nodiscard]] SegmentBoxContact segmentBoxContact(const Eigen::Vector3d& a,
                                                  const Eigen::Vector3d& b,
                                                  const Eigen::Vector3d& lo,
                                                  const Eigen::Vector3d& hi, double r2);

}  // namespace densemap
