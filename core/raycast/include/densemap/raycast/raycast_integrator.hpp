#pragma once

#include <tbb/enumerable_thread_specific.h>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

struct RaycastOptions {
  /// Rays longer than this are cut and their end is not occupied; < 0 means unlimited
  /// (OctoMap's convention).
  double max_range_m = -1.0;
};

/// What integrating one scan did; the benchmark's per-scan figures.
struct ScanStats {
  std::size_t points = 0;
  std::size_t visits = 0;   // cells marked while traversing rays (with repeats)
  std::size_t updated = 0;  // distinct cells updated
  std::size_t changed = 0;  // cells whose log-odds changed or that became known
};

/// The plain method: every ray traversed on its own, the scan's candidate sets built in
/// parallel (TBB, one update set per worker, merged by OR), then applied once.
/// The result is OctoMap's `insertPointCloud(cloud, origin, max_range, false, false)` cell for
/// cell, for any thread count. Runs in the caller's task arena.
/// Thread-safety: one integrate() at a time per integrator (it reuses per-worker buffers).
class RaycastIntegrator {
 public:
  explicit RaycastIntegrator(const RaycastOptions& options = {}) : options_(options) {}

  /// Integrates one scan; appends the cells it changed to `changes` when given.
  ScanStats integrate(OccupancyMap& map, const PointCloud& points_world,
                      const Point3f& origin_world, CellChanges* changes = nullptr);

  /// Builds the update set without applying it; returns cells visited.
  std::size_t computeUpdate(const VoxelGrid& grid, const PointCloud& points_world,
                            const Point3f& origin_world, ScanUpdate& update);

 private:
  struct Local {
    ScanUpdate update;
    std::size_t visits = 0;
  };
  RaycastOptions options_;
  tbb::enumerable_thread_specific<Local> locals_;
  ScanUpdate merged_;
};

}  // namespace densemap
