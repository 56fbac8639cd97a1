#pragma once

#include <cstdint>
#include <functional>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/sim/oracle_labels.hpp"
#include "eval_options.hpp"

namespace densemap::tools {

/// What a map integrates of one scan.
struct EvalScan {
  PointCloud train;
  Point3f origin;
};

struct TestPoint {
  Point3f x;
  bool occupied;
};

/// The hold-out split and the free test points, reproducible from the seed: each scan's points
/// are split 80/20 by a seeded hash; the 20% are occupied test points, and one point drawn
/// uniformly on each of their rays (short of the end voxel) is a free test point.
void split(const PointCloud& points, const Point3f& origin, std::uint64_t seed, std::uint64_t scan,
           double resolution, EvalScan& out, std::vector<TestPoint>& tests);

/// The xy box of the data, for slice pictures.
struct SliceFrame {
  double x0 = 0, y0 = 0;
  int cols = 0, rows = 0;
};

/// The scans of a run (world frame, non-finite points dropped; densified when asked) and the
/// slice pictures' frame.
struct EvalData {
  std::vector<PointCloud> clouds;
  std::vector<Point3f> origins;
  SliceFrame frame;
};
[[nodiscard]] Expected<EvalData> loadEvalData(const EvalOptions& o);

/// Writes a z-slice of p (probability of occupancy at a point) as PREFIX_<name>.png, like the
/// paper's grayscale insets: white free, black occupied, gray 0.5 (and unknown); north up.
[[nodiscard]] Expected<void> writeSlice(const EvalOptions& o, const SliceFrame& frame,
                                        const std::string& name,
                                        const std::function<double(const Point3f&)>& p);

/// The oracle protocol's test cells (their centres and labels); their slice too when asked.
[[nodiscard]] Expected<std::vector<TestPoint>> oracleTests(const EvalOptions& o,
                                                           const SliceFrame& frame);

}  // namespace densemap::tools
