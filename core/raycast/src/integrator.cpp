#include "densemap/raycast/integrator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <chrono>
#include <mutex>
#include <optional>
#include <string>

#include "densemap/geometry/stopwatch.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/raycast/ray_ends.hpp"

namespace densemap {
namespace {

/// Grows `box` to hold `k`.
[[gnu::always_inline]] inline void growBox(KeyBox& box, const VoxelKey& k) {
  box.min.x = std::min(box.min.x, k.x);
  box.min.y = std::min(box.min.y, k.y);
  box.min.z = std::min(box.min.z, k.z);
  box.max.x = std::max(box.max.x, k.x);
  box.max.y = std::max(box.max.y, k.y);
  box.max.z = std::max(box.max.z, k.z);
}

}  // namespace

std::string_view methodName(IntegrationMethod method) {
  switch (method) {
    case IntegrationMethod::kRaycast:
      return "raycast";
    case IntegrationMethod::kSuperRay:
      return "superray";
    case IntegrationMethod::kCulling:
      return "culling";
    case IntegrationMethod::kSuperRayCulling:
      return "superray+culling";
  }
  return "unknown";
}

Expected<IntegrationMethod> parseIntegrationMethod(std::string_view name) {
  for (const auto m : {IntegrationMethod::kRaycast, IntegrationMethod::kSuperRay,
                       IntegrationMethod::kCulling, IntegrationMethod::kSuperRayCulling}) {
    if (name == methodName(m)) return m;
  }
  return makeError("unknown integration method '" + std::string(name) +
                   "' (expected raycast, superray, culling or superray+culling)");
}

/// One scan's plan: its box, which stages run, and the levels its rays are marked in.
struct Integrator::ScanPlan {
  std::optional<VoxelKey> origin_key;
  KeyBox box{};               // the sensor's voxel and the rays' end voxels: every traversal's box
  bool grouping = false;      // super rays
  bool build_region = false;  // a culling region
  bool dense = false;         // per-worker dense marks over `box` (kSet)
  bool share_frame = false;   // the region's query bricks on the dense marks' frame
  bool grow_levels = false;   // the region grows by the scan's own marks between levels
  bool queue_walks = false;   // walks queued and walked in lanes
  std::vector<std::size_t> strides;  // level l marks the rays at multiples of strides[l]
};

std::optional<KeyBox> Integrator::findRayEnds(const VoxelGrid& grid, const PointCloud& points_world,
                                              const Point3f& origin_world) {
  // Each range's box of end voxels, joined under a lock.
  rays_.resize(points_world.size());
  std::optional<KeyBox> ends;
  std::mutex ends_mutex;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points_world.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      KeyBox local{};
                      bool any = false;
                      rayEndsInto(grid, origin_world, points_world.data() + range.begin(),
                                  range.size(), options_.max_range_m, rays_.data() + range.begin());
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        const RayEnd& r = rays_[i];
                        if (!r.key_valid) continue;
                        if (!any) local = {r.key, r.key};
                        any = true;
                        growBox(local, r.key);
                      }
                      if (!any) return;
                      const std::lock_guard lock(ends_mutex);
                      if (!ends) ends = local;
                      growBox(*ends, local.min);
                      growBox(*ends, local.max);
                    });
  return ends;
}

Integrator::ScanPlan Integrator::planScan(const VoxelGrid& grid, const Point3f& origin_world,
                                          const std::optional<KeyBox>& ends) {
  ScanPlan plan;
  plan.grouping = options_.method == IntegrationMethod::kSuperRay ||
                  options_.method == IntegrationMethod::kSuperRayCulling;
  const bool culling = options_.method == IntegrationMethod::kCulling ||
                       options_.method == IntegrationMethod::kSuperRayCulling;
  // The box of every traversal: the sensor's voxel and the rays' end voxels (grouping rays
  // keeps both it and the voxels rays end in, which the culling region needs).
  plan.origin_key = grid.pointToKey(origin_world);
  hit_.clear();
  if (plan.origin_key) {
    plan.box = {*plan.origin_key, *plan.origin_key};
    if (ends) {
      growBox(plan.box, ends->min);
      growBox(plan.box, ends->max);
    }
    if (culling) {
      for (const RayEnd& r : rays_) {
        if (r.key_valid && r.occupied) hit_.push_back(r.key);
      }
    }
  }
  plan.build_region = culling && plan.origin_key.has_value();
  plan.dense = options_.rule == UpdateRule::kSet && plan.origin_key.has_value() &&
               options_.dense_marks_max_blocks > 0;
  // The region's query bricks cover the whole rays box — the layout of every worker's dense
  // free marks, so one index serves both — unless that is more blocks than the dense marks
  // allow or than the culling box's own bricks could take (culling_max_voxels).
  std::size_t box_blocks = 1;
  for (int a = 0; a < 3; ++a) {
    box_blocks *= static_cast<std::size_t>((plan.box.max[a] >> block::kShift) -
                                           (plan.box.min[a] >> block::kShift)) +
                  1;
  }
  plan.share_frame =
      plan.dense && box_blocks <= std::min(options_.dense_marks_max_blocks,
                                           options_.culling_max_voxels / block::kVoxels);
  // The region grows by the scan's own marks between levels of rays (kSet with dense marks
  // sharing its frame only).
  for (const std::size_t s : options_.grow_strides) {
    if (s > 1) plan.strides.push_back(s);
  }
  // Growing pays when the later levels' rays stop early: it turns their walks backward (dearer
  // per voxel than forward ones when the map's region is empty) and sweeps the box again. So a
  // scan grows when the last scan that grew culled at least grow_min_share of its later levels'
  // voxels, or every grow_probe_every scans to measure again (a moving 64-beam sensor culls
  // little there; an indoor scan culls most of it).
  plan.grow_levels = plan.build_region && plan.share_frame && !plan.strides.empty();
  if (plan.grow_levels && grow_share_ < options_.grow_min_share &&
      ++scans_since_grown_ < options_.grow_probe_every) {
    plan.grow_levels = false;
  }
  if (!plan.grow_levels) plan.strides.clear();
  plan.strides.push_back(1);  // the last level takes every ray not marked yet
  // Queues pay where the processor walks them in lanes (IntegratorOptions::queue_walks).
  plan.queue_walks =
      options_.queue_walks && (DenseMarks::hasWideWalks() || DenseMarks::hasFourWalks());
  return plan;
}

const CullingRegion* Integrator::groupAndCull(const OccupancyMap& map, const Point3f& origin_world,
                                              const ScanPlan& plan, ScanStats& stats) {
  const VoxelGrid& grid = map.grid();
  double ms_region_only = 0;
  const auto group = [&] {
    if (!plan.grouping) return;
    const SuperRayStats s =
        super_rays_.build(grid, origin_world, rays_, options_.superray_min_points);
    stats.super_rays = s.super_rays;
    stats.rays = rays_.size();
  };
  const auto cull = [&] {
    if (!plan.build_region) return;
    auto t_region = std::chrono::steady_clock::now();
    std::size_t max_voxels = options_.culling_max_voxels;
    if (plan.grow_levels) {
      max_voxels = std::min(max_voxels, options_.grow_max_voxels);
    }
    region_.build(map, *plan.origin_key, cullingBox(*plan.origin_key, plan.box, max_voxels), hit_,
                  plan.share_frame ? &plan.box : nullptr, plan.grow_levels);
    ms_region_only = msSince(t_region);
  };
  // Super rays and the culling region are independent: built side by side (the region build
  // is serial; the super-ray build's parallel loops fill the other threads).
  if (plan.grouping && plan.build_region) {
    tbb::parallel_invoke(group, cull);
  } else {
    group();
    cull();
  }
  stats.ms_region = ms_region_only;
  if (!plan.build_region) return nullptr;
  stats.region_voxels = region_.size();
  // An empty region culls nothing: the forward walk is cheaper per step than the backward one.
  return region_.size() != 0 ? &region_ : nullptr;
}

void Integrator::markLevel(const VoxelGrid& grid, const Point3f& origin_world, const ScanPlan& plan,
                           std::size_t level, const CullingRegion* region) {
  const std::size_t stride = plan.strides[level];
  const std::size_t previous = level == 0 ? 0 : plan.strides[level - 1];
  const auto mark_one = [&](std::size_t i, auto& sink, Local& local) {
    if (region != nullptr) {
      markRayCulled(grid, origin_world, rays_[i], *region, local.scratch, sink, local.counts,
                    &*plan.origin_key);
    } else {
      markRay(grid, origin_world, rays_[i], sink, local.counts,
              plan.origin_key ? &*plan.origin_key : nullptr);
    }
  };
  // Indices 0, stride, 2 stride, ... below the ray count (no `size + stride - 1`: a stride
  // near SIZE_MAX would wrap it and leave ray 0 unmarked).
  const std::size_t count = rays_.empty() ? 0 : (rays_.size() - 1) / stride + 1;
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, count, std::max<std::size_t>(1, 256 / stride)),
      [&](const tbb::blocked_range<std::size_t>& range) {
        Local& local = locals_.local();
        if (!local.dense_ok) {
          // A worker that joined after resetLocals (or no dense box).
          local.dense_ok = plan.dense && local.dense.reset(plan.box.min, plan.box.max,
                                                           options_.dense_marks_max_blocks);
        }
        // The range's rays of this level, by index (those at a multiple of the previous
        // level's stride were marked by then).
        const auto idsOf = [&](const tbb::blocked_range<std::size_t>& r,
                               std::vector<std::uint32_t>& ids) {
          ids.clear();
          for (std::size_t j = r.begin(); j != r.end(); ++j) {
            const std::size_t i = j * stride;
            if (previous != 0 && i % previous == 0) continue;
            ids.push_back(static_cast<std::uint32_t>(i));
          }
          return std::span<const std::uint32_t>(ids);
        };
        const auto mark_all = [&](auto& sink) {
          for (const std::uint32_t i : idsOf(range, local.ids)) mark_one(i, sink, local);
        };
        const bool shared = local.dense_ok && region != nullptr && region->sharesFrame(local.dense);
        if (shared && plan.queue_walks) {
          // Backward walks queued and walked together at the range's end; those handed over
          // (near-ties) walked again one by one, exactly.
          SharedFrameSink sink{{local.dense, local.update}};
          markRaysCulledQueued(grid, origin_world, rays_.data(), idsOf(range, local.ids), *region,
                               local.scratch, sink, local.counts, *plan.origin_key);
          local.handed.clear();
          const DenseMarks::BackWalkCounts walked =
              local.dense.markQueuedBack(region->frameMasks(), local.handed, options_.walk_kernel);
          local.counts.visits += walked.visits;
          local.counts.culled += walked.culled;
          for (const std::uint32_t i : local.handed) {
            markCrossedCulled(grid, origin_world, rays_[i], *region, local.scratch, sink,
                              local.counts, &*plan.origin_key);
          }
        } else if (shared) {
          SharedFrameSink sink{{local.dense, local.update}};
          mark_all(sink);
        } else if (local.dense_ok && region == nullptr && plan.queue_walks) {
          // Forward walks queued and walked together at the range's end.
          DenseSink sink{local.dense, local.update};
          markRaysQueued(grid, origin_world, rays_.data(), idsOf(range, local.ids), sink,
                         local.counts, *plan.origin_key,
                         DenseMarks::queuesFixed(options_.walk_kernel), options_.walk_kernel);
          walkRaysQueued(grid, origin_world, rays_.data(), sink, *plan.origin_key,
                         options_.walk_kernel, local.handed);
        } else if (local.dense_ok) {
          DenseSink sink{local.dense, local.update};
          mark_all(sink);
        } else {
          mark_all(local.update);
        }
      });
}

const CullingRegion* Integrator::growRegion(double& ms_grow) {
  covered_.clear();
  for (Local& local : locals_) {
    if (!local.dense_ok) continue;
    // Only the blocks of the region's box (it may be smaller than the rays' box): the list
    // is bounded by the box, not by how far the rays reach.
    local.dense.forEachMarkedFree([&](std::uint64_t key, const block::BlockMask& mask) {
      if (region_.boxHasBlock(key)) covered_.push_back({key, mask});
    });
  }
  auto t_grow = std::chrono::steady_clock::now();
  region_.grow(covered_);
  ms_grow += msSince(t_grow);
  return region_.size() != 0 ? &region_ : nullptr;
}

void Integrator::mergeInto(ScanUpdate& update, ScanStats& stats) {
  update.reset(options_.rule);
  // The workers' dense marks (all over the same box) ORed into one by block index, then one
  // flush into the update; each worker's own update holds only its marks outside the box.
  DenseMarks* dense_marks = nullptr;
  others_.clear();
  for (Local& local : locals_) {
    if (!local.dense_ok) continue;
    if (dense_marks == nullptr) {
      dense_marks = &local.dense;
    } else {
      others_.push_back(&local.dense);
    }
  }
  if (dense_marks != nullptr) dense_marks->flushAllInto(others_, update, tbbRunner());
  for (Local& local : locals_) {
    update.merge(local.update);
    stats.visits += local.counts.visits;
    stats.culled += local.counts.culled;
  }
}

ScanStats Integrator::computeUpdate(const OccupancyMap& map, const PointCloud& points_world,
                                    const Point3f& origin_world, ScanUpdate& update) {
  const VoxelGrid& grid = map.grid();
  ScanStats stats;
  stats.points = points_world.size();
  auto t0 = std::chrono::steady_clock::now();

  // 1. The rays' ends; the plan; super rays and the culling region side by side.
  const std::optional<KeyBox> ends = findRayEnds(grid, points_world, origin_world);
  stats.rays = rays_.size();
  const ScanPlan plan = planScan(grid, origin_world, ends);
  const CullingRegion* region = groupAndCull(map, origin_world, plan, stats);
  // Stage times sum to the wall time: the region's own build time (overlapped with the
  // super-ray build when both run), and the rest of this span as the rays stage.
  stats.ms_rays = msSince(t0) - stats.ms_region;

  // 2. The rays' walks into per-worker marks, level by level; the region grows in between.
  for (Local& local : locals_) {
    local.update.reset(options_.rule);
    local.counts = {};
    local.dense_ok = plan.dense &&
                     local.dense.reset(plan.box.min, plan.box.max, options_.dense_marks_max_blocks);
  }
  std::size_t visits_before_later = 0, culled_before_later = 0;  // after level 0
  double ms_grow = 0;
  for (std::size_t level = 0; level < plan.strides.size(); ++level) {
    markLevel(grid, origin_world, plan, level, region);
    if (level + 1 == plan.strides.size()) break;
    if (level == 0) {
      for (const Local& local : locals_) {
        visits_before_later += local.counts.visits;
        culled_before_later += local.counts.culled;
      }
    }
    region = growRegion(ms_grow);
    stats.region_voxels = region_.size();
  }
  // The region's growths count as region time (the mark stage is the walks only).
  stats.ms_region += ms_grow;
  stats.ms_mark = msSince(t0) - ms_grow;

  // 3. The workers' marks merged into one update.
  mergeInto(update, stats);
  if (plan.grow_levels) {
    const double later_visits = static_cast<double>(stats.visits - visits_before_later);
    const double later_culled = static_cast<double>(stats.culled - culled_before_later);
    grow_share_ =
        later_visits + later_culled > 0 ? later_culled / (later_visits + later_culled) : 1.0;
    scans_since_grown_ = 0;
  }
  stats.ms_merge = msSince(t0);
  return stats;
}

ScanStats Integrator::integrate(OccupancyMap& map, const PointCloud& points_world,
                                const Point3f& origin_world, CellChanges* changes) {
  ScanStats stats = computeUpdate(map, points_world, origin_world, merged_);
  auto t0 = std::chrono::steady_clock::now();
  const ApplyStats applied = map.apply(merged_, changes);
  stats.ms_apply = msSince(t0);
  stats.updated = applied.updated_cells;
  stats.changed = applied.changed_cells;
  return stats;
}

}  // namespace densemap
