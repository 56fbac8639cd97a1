#pragma once

#include <cstddef>

#include "densemap/geometry/point_cloud.hpp"

namespace densemap::eval {

/// How well a reconstructed point cloud covers a true one, compared as sets of occupied voxels
/// (dissertation Table 4.1: IoU, precision, recall and F1 on a 0.1 m grid).
struct PointSetMetrics {
  std::size_t predicted_voxels = 0, true_voxels = 0, common_voxels = 0;
  double iou = 0.0;        // common / union
  double precision = 0.0;  // common / predicted
  double recall = 0.0;     // common / true
  double f1 = 0.0;
};

/// Non-finite points and points outside the grid's addressable range are ignored.
[[nodiscard]] PointSetMetrics comparePointSets(const PointCloud& predicted,
                                               const PointCloud& truth, double voxel_m);

}  // namespace densemap::eval
