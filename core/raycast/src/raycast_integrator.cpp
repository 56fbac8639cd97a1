#include "densemap/raycast/raycast_integrator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "densemap/raycast/ray_marking.hpp"

namespace densemap {

std::size_t RaycastIntegrator::computeUpdate(const VoxelGrid& grid, const PointCloud& points_world,
                                             const Point3f& origin_world, ScanUpdate& update) {
  for (Local& local : locals_) {
    local.update.clear();
    local.visits = 0;
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points_world.size(), 512),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      Local& local = locals_.local();
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        local.visits += markRay(grid, origin_world, points_world[i],
                                                options_.max_range_m, local.update);
                      }
                    });
  std::size_t visits = 0;
  update.clear();
  for (Local& local : locals_) {
    update.merge(local.update);
    visits += local.visits;
  }
  return visits;
}

ScanStats RaycastIntegrator::integrate(OccupancyMap& map, const PointCloud& points_world,
                                       const Point3f& origin_world, CellChanges* changes) {
  ScanStats stats;
  stats.points = points_world.size();
  stats.visits = computeUpdate(map.grid(), points_world, origin_world, merged_);
  const ApplyStats applied = map.apply(merged_, changes);
  stats.updated = applied.updated_cells;
  stats.changed = applied.changed_cells;
  return stats;
}

}  // namespace densemap
