#include "densemap/raycast/integrator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <chrono>
#include <mutex>
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

ScanStats Integrator::computeUpdate(const OccupancyMap& map, const PointCloud& points_world,
                                    const Point3f& origin_world, ScanUpdate& update) {
  const VoxelGrid& grid = map.grid();
  const bool grouping = options_.method == IntegrationMethod::kSuperRay ||
                        options_.method == IntegrationMethod::kSuperRayCulling;
  const bool culling = options_.method == IntegrationMethod::kCulling ||
                       options_.method == IntegrationMethod::kSuperRayCulling;
  ScanStats stats;
  stats.points = points_world.size();
  auto t0 = std::chrono::steady_clock::now();

  // The rays' ends, and the box of their end voxels (each range's, joined under a lock).
  rays_.resize(points_world.size());
  KeyBox ends{};
  bool any_end = false;
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
                      if (!any_end) ends = local;
                      any_end = true;
                      growBox(ends, local.min);
                      growBox(ends, local.max);
                    });
  stats.rays = rays_.size();

  // The box of every traversal: the sensor's voxel and the rays' end voxels (grouping rays
  // keeps both it and the voxels rays end in, which the culling region needs).
  const auto origin_key = grid.pointToKey(origin_world);
  KeyBox box{};
  hit_.clear();
  if (origin_key) {
    box = {*origin_key, *origin_key};
    if (any_end) {
      growBox(box, ends.min);
      growBox(box, ends.max);
    }
    if (culling) {
      for (const RayEnd& r : rays_) {
        if (r.key_valid && r.occupied) hit_.push_back(r.key);
      }
    }
  }
  // Super rays and the culling region are independent: built side by side (the region build
  // is serial; the super-ray build's parallel loops fill the other threads).
  const bool build_region = culling && origin_key.has_value();
  const bool dense = options_.rule == UpdateRule::kSet && origin_key.has_value() &&
                     options_.dense_marks_max_blocks > 0;
  // The region's query bricks cover the whole rays box — the layout of every worker's dense
  // free marks, so one index serves both — unless that is more blocks than the dense marks
  // allow or than the culling box's own bricks could take (culling_max_voxels).
  std::size_t box_blocks = 1;
  for (int a = 0; a < 3; ++a) {
    box_blocks *=
        static_cast<std::size_t>((box.max[a] >> block::kShift) - (box.min[a] >> block::kShift)) + 1;
  }
  const bool share_frame =
      dense && box_blocks <= std::min(options_.dense_marks_max_blocks,
                                      options_.culling_max_voxels / block::kVoxels);
  // The region grows by the scan's own marks between levels of rays (kSet with dense marks
  // sharing its frame only).
  std::vector<std::size_t> strides;
  for (const std::size_t s : options_.grow_strides) {
    if (s > 1) strides.push_back(s);
  }
  // Growing pays when the later levels' rays stop early: it turns their walks backward (dearer
  // per voxel than forward ones when the map's region is empty) and sweeps the box again. So a
  // scan grows when the last scan that grew culled at least grow_min_share of its later levels'
  // voxels, or every grow_probe_every scans to measure again (a 64-beam drive at 0.1 m culled
  // 11%, and its growing scans were slower; an indoor scan at 0.2 m, 56%).
  bool grow_levels = build_region && share_frame && !strides.empty();
  if (grow_levels && grow_share_ < options_.grow_min_share &&
      ++scans_since_grown_ < options_.grow_probe_every) {
    grow_levels = false;
  }
  if (!grow_levels) strides.clear();
  double ms_region_only = 0;
  const auto group = [&] {
    if (!grouping) return;
    const SuperRayStats s =
        super_rays_.build(grid, origin_world, rays_, options_.superray_min_points);
    stats.super_rays = s.super_rays;
    stats.rays = rays_.size();
  };
  const auto cull = [&] {
    if (!build_region) return;
    auto t_region = std::chrono::steady_clock::now();
    std::size_t max_voxels = options_.culling_max_voxels;
    if (grow_levels) {
      max_voxels = std::min(max_voxels, options_.grow_max_voxels);
    }
    region_.build(map, *origin_key, cullingBox(*origin_key, box, max_voxels), hit_,
                  share_frame ? &box : nullptr, grow_levels);
    ms_region_only = msSince(t_region);
  };
  if (grouping && build_region) {
    tbb::parallel_invoke(group, cull);
  } else {
    group();
    cull();
  }
  const CullingRegion* region = nullptr;
  if (build_region) {
    // An empty region culls nothing: the forward walk is cheaper per step than the backward one.
    if (region_.size() != 0) region = &region_;
    stats.region_voxels = region_.size();
  }
  // Stage times sum to the wall time: the region's own build time (overlapped with the
  // super-ray build when both run), and the rest of this span as the rays stage.
  stats.ms_rays = msSince(t0) - ms_region_only;
  stats.ms_region = ms_region_only;

  for (Local& local : locals_) {
    local.update.reset(options_.rule);
    local.counts = {};
    local.dense_ok = dense && local.dense.reset(box.min, box.max, options_.dense_marks_max_blocks);
  }
  // Queues pay where the processor walks them in lanes (IntegratorOptions::queue_walks).
  const bool queue_forward =
      options_.queue_walks && (DenseMarks::hasWideWalks() || DenseMarks::hasFourWalks());
  const bool queue_backward = queue_forward;
  const auto mark_one = [&](std::size_t i, auto& sink, Local& local) {
    if (region != nullptr) {
      markRayCulled(grid, origin_world, rays_[i], *region, local.scratch, sink, local.counts,
                    &*origin_key);
    } else {
      markRay(grid, origin_world, rays_[i], sink, local.counts,
              origin_key ? &*origin_key : nullptr);
    }
  };
  // Level l marks the rays whose index is a multiple of strides[l] but not of strides[l - 1]
  // (those were marked by level l - 1 or earlier): each ray once, at the first level whose
  // stride divides its index; the last level (stride 1) takes the rest.
  strides.push_back(1);
  std::size_t visits_before_later = 0, culled_before_later = 0;  // after level 0
  double ms_grow = 0;
  for (std::size_t level = 0; level < strides.size(); ++level) {
    const std::size_t stride = strides[level];
    const std::size_t previous = level == 0 ? 0 : strides[level - 1];
    // Indices 0, stride, 2 stride, ... below the ray count (no `size + stride - 1`: a stride
    // near SIZE_MAX would wrap it and leave ray 0 unmarked).
    const std::size_t count = rays_.empty() ? 0 : (rays_.size() - 1) / stride + 1;
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, count, std::max<std::size_t>(1, 256 / stride)),
        [&](const tbb::blocked_range<std::size_t>& range) {
          Local& local = locals_.local();
          if (!local.dense_ok) {
            // A worker that joined after the reset above (or no dense box).
            local.dense_ok =
                dense && local.dense.reset(box.min, box.max, options_.dense_marks_max_blocks);
          }
          // The range's rays of this level, by index.
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
          if (local.dense_ok && region != nullptr && region->sharesFrame(local.dense) &&
              queue_backward) {
            // Backward walks queued and walked together at the range's end; those handed over
            // (near-ties) walked again one by one, exactly.
            SharedFrameSink sink{{local.dense, local.update}};
            markRaysCulledQueued(grid, origin_world, rays_.data(), idsOf(range, local.ids), *region,
                                 local.scratch, sink, local.counts, *origin_key);
            local.handed.clear();
            const DenseMarks::BackWalkCounts walked = local.dense.markQueuedBack(
                region->frameMasks(), local.handed, options_.walk_kernel);
            local.counts.visits += walked.visits;
            local.counts.culled += walked.culled;
            for (const std::uint32_t i : local.handed) {
              markCrossedCulled(grid, origin_world, rays_[i], *region, local.scratch, sink,
                                local.counts, &*origin_key);
            }
          } else if (local.dense_ok && region != nullptr && region->sharesFrame(local.dense)) {
            SharedFrameSink sink{{local.dense, local.update}};
            mark_all(sink);
          } else if (local.dense_ok && region == nullptr && queue_forward) {
            // Forward walks queued and walked together at the range's end.
            DenseSink sink{local.dense, local.update};
            markRaysQueued(grid, origin_world, rays_.data(), idsOf(range, local.ids), sink,
                           local.counts, *origin_key,
                           DenseMarks::queuesFixed(options_.walk_kernel), options_.walk_kernel);
            walkRaysQueued(grid, origin_world, rays_.data(), sink, *origin_key,
                           options_.walk_kernel, local.handed);
          } else if (local.dense_ok) {
            DenseSink sink{local.dense, local.update};
            mark_all(sink);
          } else {
            mark_all(local.update);
          }
        });
    if (level + 1 == strides.size()) break;
    if (level == 0) {
      for (const Local& local : locals_) {
        visits_before_later += local.counts.visits;
        culled_before_later += local.counts.culled;
      }
    }
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
    region = region_.size() != 0 ? &region_ : nullptr;
    stats.region_voxels = region_.size();
  }
  // The region's growths count as region time (the mark stage is the walks only).
  stats.ms_region += ms_grow;
  stats.ms_mark = msSince(t0) - ms_grow;
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
  if (grow_levels) {
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
