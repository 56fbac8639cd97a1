#pragma once

// What planner queries take and answer: plain data (no map internals), for the SDK's users.
#include <Eigen/Geometry>

#include <cstddef>
#include <optional>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/voxel_key.hpp"
#include "densemap/query/cell_state.hpp"

namespace densemap {

struct DistanceQueryOptions {
  /// Unknown cells count as obstacles (a cautious planner's choice), else as free.
  bool unknown_as_occupied = false;
  /// Distances and gradients interpolated trilinearly between the 8 cell centres around each
  /// point, else those of the point's cell.
  bool interpolate = false;
  /// Also find each point's nearest obstacle (a search per point; the gradient of an
  /// uninterpolated query needs it too).
  bool nearest = true;
};

/// Per point: the distance (metres) to the nearest obstacle, at most the field's maximum
/// (which means "none within it"); the gradient of the distance (x y z: unit length, pointing
/// away from the nearest obstacle, when taken from it; the interpolant's when interpolated;
/// zero at an obstacle or beyond the maximum); the centre of the nearest obstacle cell (x y z,
/// NaN where none within the maximum, or not asked).
struct DistanceQueryResult {
  std::vector<float> distances;
  std::vector<float> gradients;
  std::vector<float> nearest;
};

/// An oriented box: centre, half extents (metres, >= 0) and rotation (world from box).
struct OrientedBox {
  Point3f center = Point3f::Zero();
  Point3f half_extents = Point3f::Zero();
  Eigen::Quaternionf rotation = Eigen::Quaternionf::Identity();
};

/// A cell a swept volume touches, and where it is first touched: metres of arc from the
/// path's first vertex (a path), or the index of the box (boxes).
struct SweptConflict {
  VoxelKey cell{};
  Point3f center = Point3f::Zero();
  double arc_length = 0.0;
  std::size_t index = 0;  // the segment (path) or box it was found in
};

/// Every cell the volume touches counted: occupied when any is occupied (`occupied` is the
/// first along the path), else unknown when any is unknown, else free. `unknown` is the first
/// unknown cell before the first occupied one (on the whole path when none is occupied).
struct SweptVolumeResult {
  CellState state = CellState::kFree;
  std::optional<SweptConflict> occupied;
  std::optional<SweptConflict> unknown;
  double length_m = 0.0;         // of the path (0 for boxes)
  std::size_t cells_tested = 0;  // cells not free whose geometry was tested
};

}  // namespace densemap
