#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "densemap/planner/distance_field.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

/// The layer of cells holding height `z_m`, as points x y z (cell centres) with their distance
/// (metres): every cell of the layer within the field's maximum of an occupied cell, in the
/// field's block order. What a ROS tool colours by distance (PointCloud2 with a distance field).
[[nodiscard]] std::vector<std::array<float, 4>> distanceSlice(const DistanceField& field,
                                                              double z_m);

/// A costmap of the layer of cells holding `z_m` (nav_msgs/OccupancyGrid's values), over the
/// x-y box of the map's blocks in that layer: 100 where an occupied cell is within
/// `robot_radius_m` (cell centre to cell centre: the robot there would touch it), else 0 where
/// the cell is known, -1 where it is unknown. Rows along x, from the box's lower corner.
struct Costmap {
  double origin_x = 0.0, origin_y = 0.0;  // the lower corner of cell (0, 0), metres
  double resolution = 0.0;
  std::uint32_t width = 0, height = 0;
  std::vector<std::int8_t> data;
};
/// The most cells a costmap holds (64 MiB).
inline constexpr std::size_t kMaxCostmapCells = std::size_t{1} << 26;
/// `field` and `view` of the same version; an empty costmap for an empty layer or one of more
/// than kMaxCostmapCells cells.
[[nodiscard]] Costmap inflatedCostmap(const DistanceField& field, const MapView& view, double z_m,
                                      double robot_radius_m);

}  // namespace densemap
