#include "densemap/eval/point_set_metrics.hpp"

#include <algorithm>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"

namespace densemap::eval {
namespace {

std::vector<std::uint64_t> voxelsOf(const PointCloud& points, const VoxelGrid& grid) {
  std::vector<std::uint64_t> keys;
  keys.reserve(points.size());
  for (const Point3f& p : points) {
    if (!p.allFinite()) continue;
    if (const auto k = grid.pointToKey(p)) keys.push_back(k->packed());
  }
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  return keys;
}

}  // namespace

PointSetMetrics comparePointSets(const PointCloud& predicted, const PointCloud& truth,
                                 double voxel_m) {
  const VoxelGrid grid(voxel_m);
  const auto a = voxelsOf(predicted, grid);
  const auto b = voxelsOf(truth, grid);
  std::vector<std::uint64_t> common;
  std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(common));
  PointSetMetrics m;
  m.predicted_voxels = a.size();
  m.true_voxels = b.size();
  m.common_voxels = common.size();
  const double union_size = static_cast<double>(a.size() + b.size() - common.size());
  if (union_size > 0) m.iou = static_cast<double>(common.size()) / union_size;
  if (!a.empty()) m.precision = static_cast<double>(common.size()) / static_cast<double>(a.size());
  if (!b.empty()) m.recall = static_cast<double>(common.size()) / static_cast<double>(b.size());
  if (m.precision + m.recall > 0) m.f1 = 2 * m.precision * m.recall / (m.precision + m.recall);
  return m;
}

}  // namespace densemap::eval
