#pragma once

#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <type_traits>
#include <utility>

#include "densemap/traversal/backward_traversal.hpp"
#include "densemap/traversal/ray_traversal.hpp"
#include "densemap/traversal/dense_marks.hpp"
#include "densemap/traversal/scan_update.hpp"

namespace densemap {

/// One ray to mark — a measurement, or a super ray standing for `weight` measurements whose
/// traversals are identical: where it ends (after the max-range cut), that end's voxel, and
/// whether the end voxel is occupied (false for rays cut at max range).
struct RayEnd {
  Point3f end;
  VoxelKey key;  // grid.pointToKey(end) when key_valid
  std::uint32_t weight = 1;
  bool key_valid = false;  // end inside the addressable range
  bool occupied = true;
};

/// rayEndFor written into `ray` in place (the integrator's loop: a RayEnd returned and copied
/// was read back, 8 bytes at a time, from its key's 2-byte stores: a store-forwarding stall a
/// ray). Every member is set.
inline void rayEndInto(const VoxelGrid& grid, const Point3f& origin, const Point3f& point,
                       double max_range_m, RayEnd& ray) {
  ray.weight = 1;
  ray.occupied = true;
  const float dx = point.x() - origin.x();
  const float dy = point.y() - origin.y();
  const float dz = point.z() - origin.z();
  const double squared = static_cast<double>(dx * dx + dy * dy + dz * dz);
  // Clearly within range without the square root (its latency held up the loop): below
  // (1 - 2^-40) max^2, the rounded root is below max; the root decides the rest.
  const double norm = max_range_m < 0.0 || squared < max_range_m * max_range_m * (1 - 0x1p-40)
                          ? 0.0
                          : std::sqrt(squared);
  if (max_range_m < 0.0 || norm <= max_range_m) {
    ray.end = point;
  } else {
    // Vector3::normalized(): divide by the float-rounded double norm, then scale by (float)range.
    Point3f direction(dx, dy, dz);
    if (norm > 0.0) {
      const float len = static_cast<float>(norm);
      direction = Point3f(dx / len, dy / len, dz / len);
    }
    const float range = static_cast<float>(max_range_m);
    ray.end = Point3f(origin.x() + direction.x() * range, origin.y() + direction.y() * range,
                      origin.z() + direction.z() * range);
    ray.occupied = false;
  }
  // The key's members one by one (an optional<VoxelKey> copied whole stalled the same way).
  const auto x = grid.coordToKey(ray.end.x());
  const auto y = grid.coordToKey(ray.end.y());
  const auto z = grid.coordToKey(ray.end.z());
  ray.key_valid = x && y && z;
  ray.key.x = x.value_or(0);
  ray.key.y = y.value_or(0);
  ray.key.z = z.value_or(0);
}

/// The ray OctoMap 1.9.7's `OccupancyOcTreeBase::computeUpdate` casts for one point (no
/// bounding box): to the point itself, occupied; or, when longer than `max_range_m`
/// (< 0: unlimited), cut at that range with OctoMap's float arithmetic and not occupied.
[[nodiscard]] inline RayEnd rayEndFor(const VoxelGrid& grid, const Point3f& origin,
                                      const Point3f& point, double max_range_m) {
  RayEnd ray;
  rayEndInto(grid, origin, point, max_range_m, ray);
  return ray;
}

/// Cells marked, and cells skipped inside a culling region, while marking rays.
struct MarkCounts {
  std::size_t visits = 0;
  std::size_t culled = 0;
};

/// Where marks go under UpdateRule::kSet with a dense box: into `dense` (or `update` outside
/// its box). ScanUpdate is the other sink.
struct DenseSink {
  DenseMarks& dense;
  ScanUpdate& update;
  void markFree(const VoxelKey& k, std::uint32_t /*weight*/) { dense.markFree(k, update); }
  void markOccupied(const VoxelKey& k, std::uint32_t /*weight*/) { dense.markOccupied(k, update); }
  /// A ray's marker (markRay): the free marks' hot state in locals.
  [[nodiscard]] DenseMarks::StepMarker marker() { return DenseMarks::StepMarker(dense, update); }
};

/// A DenseSink whose culling region shares the dense box's block indexing
/// (CullingRegion::sharesFrame): the region test and the mark take one index computation.
struct SharedFrameSink : DenseSink {
  template <class Region>
  bool markFreeUnlessIn(const Region& region, const VoxelKey& k, std::uint32_t /*weight*/) {
    return dense.markFreeUnlessIn(region, k, update);
  }
};

/// A walk's fast loop marks through a DenseMarks::Cursor (in registers) when the walk stays in
/// the box: the steps of markRay's forward walks (every voxel) and of markRayCulled's backward
/// walks (until the region).
struct CursorMarkAll {
  DenseMarks::Cursor cursor;
  std::uint32_t marked = 0;
  void first() {  // the forward walk's first voxel
    cursor.mark();
    ++marked;
  }
  template <int A>
  void step() {
    cursor.template move<A>();
    cursor.mark();
    ++marked;
  }
};
struct CursorMarkUnlessCulled {
  DenseMarks::Cursor cursor;
  std::uint32_t marked = 0;
  template <int A>
  bool step() {
    cursor.template move<A>();
    if (!cursor.markUnlessCulled()) return false;
    ++marked;
    return true;
  }
};

/// What the two dense walks share: a DenseMarks::StepMarker for their steps and keys, the
/// voxels marked, and the fast loops' Steps (fastSteps in place of begin(), endFastSteps).
template <class Steps>
class MarkerWalk {
 public:
  /// The StepMarker's constructor arguments (built in place).
  template <class... Args>
  explicit MarkerWalk(Args&&... args) : marker_(std::forward<Args>(args)...) {}
  void begin(const VoxelKey& k, const int (&delta)[3]) { marker_.begin(k, delta); }
  [[nodiscard]] std::optional<Steps> fastSteps(const VoxelKey& first, const int (&delta)[3],
                                               const VoxelKey& last) {
    if (auto c = marker_.cursorFor(first, delta, last)) return Steps{*c};
    return std::nullopt;
  }
  void endFastSteps(const Steps& steps) {
    marker_.resume(steps.cursor);
    marked_ += steps.marked;
  }

 protected:
  DenseMarks::StepMarker marker_;
  std::uint32_t marked_ = 0;  // not size_t: see StepMarker's count
};

/// markRayCulled's walk through a SharedFrameSink: the fast backward walk's steps go to a
/// DenseMarks::Cursor (CursorMarkUnlessCulled: the voxel's address followed step by step, its
/// region bit and mark one word address apart), or to the StepMarker when the walk may leave
/// the box; when the walk hands over to the exact one, keys go to the sink as
/// markFreeUnlessIn takes them.
template <class Region>
class SharedFrameWalk : public MarkerWalk<CursorMarkUnlessCulled> {
 public:
  SharedFrameWalk(const Region& region, SharedFrameSink& sink)
      : MarkerWalk(sink.dense, sink.update, region.frameMasks()),
        region_(region),
        sink_(sink) {}
  template <int A>
  bool step(int coord) {
    marker_.template move<A>(coord);
    if (!marker_.markUnlessCulled()) return false;
    ++marked_;
    return true;
  }
  bool operator()(const VoxelKey& k) {
    if (stepping_) {  // the exact walk took over: the marks' own state from here on
      marker_.finish();
      stepping_ = false;
    }
    if (!sink_.markFreeUnlessIn(region_, k, 1)) return false;
    ++marked_;
    return true;
  }
  /// Voxels marked; ends the walk.
  std::size_t finish() {
    if (stepping_) marker_.finish();
    stepping_ = false;
    return marked_;
  }

 private:
  const Region& region_;
  SharedFrameSink& sink_;
  bool stepping_ = true;
};

/// markRay's forward walk through a DenseSink: the walk's steps to a DenseMarks::Cursor in
/// the counted loop (CursorMarkAll), else to the StepMarker, every voxel marked.
class ForwardWalk : public MarkerWalk<CursorMarkAll> {
 public:
  explicit ForwardWalk(DenseMarks::StepMarker marker) : MarkerWalk(marker) {}
  void first() {
    marker_.mark();
    ++marked_;
  }
  template <int A>
  void step(int coord) {
    marker_.template move<A>(coord);
    marker_.mark();
    ++marked_;
  }
  /// Voxels marked; ends the walk.
  std::size_t finish() {
    marker_.finish();
    return marked_;
  }
};

/// Marks `k` free unless `region` holds it; returns whether it marked.
template <class Region, class Sink>
bool markFreeUnlessIn(const Region& region, Sink& sink, const VoxelKey& k, std::uint32_t weight) {
  if constexpr (requires { sink.markFreeUnlessIn(region, k, weight); }) {
    return sink.markFreeUnlessIn(region, k, weight);
  } else {
    if (region.contains(k)) return false;
    sink.markFree(k, weight);
    return true;
  }
}

/// The end voxel of a ray that ends in it, `weight` times.
template <class Sink>
void markEnd(const RayEnd& ray, Sink& update, MarkCounts& counts) {
  if (ray.occupied && ray.key_valid) {
    update.markOccupied(ray.key, ray.weight);
    ++counts.visits;
  }
}

/// Marks one ray into a scan's update set (a ScanUpdate or a DenseSink) as OctoMap's
/// computeUpdate does — the cells crossed (traverseRay) free, the end voxel occupied when the
/// ray is — each `weight` times. `origin_key`, when given, is the origin's key (as in
/// markRayCulled).
template <class Sink>
void markRay(const VoxelGrid& grid, const Point3f& origin, const RayEnd& ray, Sink& update,
             MarkCounts& counts, const VoxelKey* origin_key = nullptr) {
  // Counted in a local (a count in memory was reloaded and stored at every voxel).
  std::size_t visits = 0;
  if constexpr (requires { update.marker(); }) {
    ForwardWalk walk(update.marker());
    RayKeys keys;
    const RayKeys* known = nullptr;
    if (origin_key != nullptr && ray.key_valid) {
      keys = {*origin_key, ray.key};
      known = &keys;
    }
    traverseRay(grid, origin, ray.end, walk, known);
    visits = walk.finish();
  } else {
    traverseRay(grid, origin, ray.end, [&](const VoxelKey& k) {
      update.markFree(k, ray.weight);
      ++visits;
    });
  }
  counts.visits += visits;
  markEnd(ray, update, counts);
}

/// Rays rays[id] for `ids` with a valid end key, eight at a time: `eight(ends, keys, ids, n)`
/// (n <= 8 of each); `other(id)` for the rest, in order.
template <class Eight, class Other>
void forRaysByEight(const RayEnd* rays, std::span<const std::uint32_t> ids, Eight&& eight,
                    Other&& other) {
  Point3f ends[8];
  VoxelKey keys[8];
  std::uint32_t lane_ray[8];
  int n = 0;
  for (const std::uint32_t id : ids) {
    const RayEnd& ray = rays[id];
    if (!ray.key_valid) {
      other(id);
      continue;
    }
    ends[n] = ray.end;
    keys[n] = ray.key;
    lane_ray[n++] = id;
    if (n == 8) {
      eight(ends, keys, lane_ray, n);
      n = 0;
    }
  }
  if (n != 0) eight(ends, keys, lane_ray, n);
}

/// Rays rays[id] for `ids`, their traversals started eight at a time (startTraversals):
/// `each(id, starts, lane)` in order for those whose end key is valid, `other(id)` for the rest.
template <class Each, class Other>
void startRaysByEight(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& origin_key,
                      const RayEnd* rays, std::span<const std::uint32_t> ids, Each&& each,
                      Other&& other) {
  TraversalStarts starts;
  forRaysByEight(
      rays, ids,
      [&](const Point3f* ends, const VoxelKey* keys, const std::uint32_t* lane_ray, int n) {
        startTraversals(grid, origin, origin_key, ends, keys, n, starts);
        for (int l = 0; l < n; ++l) each(lane_ray[l], starts, l);
      },
      other);
}

/// markRay for rays[id], `ids`, through a DenseSink, each forward walk queued when it can be (a
/// counted walk between two voxels of the box: every ray of the integrator's box but short ones
/// and near-ties at the end): its first voxel is marked now and the others by the sink's
/// DenseMarks::markQueued, which the caller runs before the marks are read — or, when `fixed`
/// (DenseMarks::queuesFixed(kernel)), started side by side (startTraversalLanes) and queued
/// eight at a time by the rays' indices (DenseMarks::queueFixedLanes, for `kernel`) for
/// walkRaysQueued. Other rays are marked as markRay does. Returns how many walks were queued.
inline std::size_t markRaysQueued(
    const VoxelGrid& grid, const Point3f& origin, const RayEnd* rays,
    std::span<const std::uint32_t> ids, DenseSink& sink, MarkCounts& counts,
    const VoxelKey& origin_key, bool fixed = false,
    DenseMarks::WalkKernel kernel = DenseMarks::WalkKernel::kBest) {
  std::size_t queued = 0;
  const auto marked = [&](std::uint32_t id) {
    markRay(grid, origin, rays[id], sink, counts, &origin_key);
  };
  if (fixed) {
    TraversalLanes lanes;
    forRaysByEight(
        rays, ids,
        [&](const Point3f* ends, const VoxelKey* keys, const std::uint32_t* lane_ray, int n) {
          startTraversalLanes(grid, origin, origin_key, ends, keys, n, lanes);
          const unsigned done =
              sink.dense.queueFixedLanes(lanes, n, origin_key, lane_ray, kernel);
          unsigned occupied = 0;  // the lanes whose end voxel markEnd would mark (keys[l])
          for (int l = 0; l < n; ++l) {
            const RayEnd& ray = rays[lane_ray[l]];
            if ((done >> l & 1U) != 0) {
              counts.visits += static_cast<std::size_t>(lanes.cr[0][l] + lanes.cr[1][l] +
                                                        lanes.cr[2][l]);  // (countedTotal)
              ++queued;
              occupied |= (ray.occupied ? 1U : 0U) << l;
            } else if ((lanes.same >> l & 1U) != 0 || (lanes.has_length >> l & 1U) == 0) {
              // (kSameVoxel: one voxel, nothing crossed)
              occupied |= (ray.occupied ? 1U : 0U) << l;
            } else {
              marked(lane_ray[l]);
            }
          }
          // markEnd's marks (every key here is valid) and counts, the lanes' together.
          counts.visits += static_cast<std::size_t>(std::popcount(occupied));
          for (unsigned out = sink.dense.markOccupiedLanes(keys, occupied); out != 0;
               out &= out - 1) {
            sink.update.markOccupied(keys[std::countr_zero(out)]);
          }
        },
        marked);
    return queued;
  }
  startRaysByEight(
      grid, origin, origin_key, rays, ids,
      [&](std::uint32_t id, const TraversalStarts& st, int l) {
        const RayEnd& ray = rays[id];
        if (st.kind[l] == TraversalKind::kRay) {
          const TraversalStart& s = st.start[l];
          const int total = countedTotal(st.end[l], st.crossings[l]);
          if (total == 0 ||
              !sink.dense.queueWalk(s.origin, s.step, s.end, s.t_max, s.t_delta, total,
                                    std::max(std::max(st.times[l].last[0], st.times[l].last[1]),
                                             st.times[l].last[2]))) {
            marked(id);
            return;
          }
          counts.visits += static_cast<std::size_t>(total);
          ++queued;
        }
        markEnd(ray, sink, counts);  // (one voxel: nothing crossed)
      },
      marked);
  return queued;
}

/// Walks what markRaysQueued queued into `sink` from `rays` (its `fixed` is
/// DenseMarks::queuesFixed(kernel), its `kernel` this one): DenseMarks::markQueued(kernel), or
/// markFixedQueued and the walks it hands over walked again by markRay (their counts were added
/// when queued; `handed`: scratch).
inline void walkRaysQueued(const VoxelGrid& grid, const Point3f& origin, const RayEnd* rays,
                           DenseSink& sink, const VoxelKey& origin_key,
                           DenseMarks::WalkKernel kernel, std::vector<std::uint32_t>& handed) {
  if (!DenseMarks::queuesFixed(kernel)) {
    sink.dense.markQueued(kernel);
    return;
  }
  handed.clear();
  sink.dense.markFixedQueued(handed);
  MarkCounts counted;  // (already)
  for (const std::uint32_t id : handed) markRay(grid, origin, rays[id], sink, counted, &origin_key);
}

/// markRayCulled's free marks (the crossed voxels outside the region), not the end voxel's.
template <class Region, class Sink>
void markCrossedCulled(const VoxelGrid& grid, const Point3f& origin, const RayEnd& ray,
                       const Region& region, BackwardScratch& scratch, Sink& update,
                       MarkCounts& counts, const VoxelKey* origin_key) {
  // The ends' keys when the caller has the origin's (the end's is the ray's).
  RayKeys keys;
  const RayKeys* known = nullptr;
  if (origin_key != nullptr && ray.key_valid) {
    keys = {*origin_key, ray.key};
    known = &keys;
  }
  std::size_t marked = 0, total = 0;
  if constexpr (std::is_same_v<Sink, SharedFrameSink> && requires { region.frameMasks(); }) {
    SharedFrameWalk<Region> walk(region, update);
    total = traverseRayBackward(grid, origin, ray.end, scratch, walk, known);
    marked = walk.finish();
  } else {
    // Other sinks (no dense marks, or a region in its own frame): key by key.
    total = traverseRayBackward(
        grid, origin, ray.end, scratch,
        [&](const VoxelKey& k) {
          if (!markFreeUnlessIn(region, update, k, ray.weight)) return false;
          ++marked;
          return true;
        },
        known);
  }
  counts.visits += marked;
  counts.culled += total - marked;
}

/// markRay with a culling region (dissertation Sec. 2.3.5): the ray is traversed from its end
/// back toward the sensor and stops at the first voxel inside the region. That is exact: the
/// region is closed toward the sensor's voxel along each axis and a traversal moves
/// monotonically away from that voxel, so every voxel before it on the ray is inside too — and
/// inside, free updates cannot change the map (fully free, not ended in by this scan's rays).
/// `Region` needs `bool contains(const VoxelKey&) const`. `origin_key`, when given, is the
/// origin's key (the walk then takes the ends' keys from it and the ray, not from their points).
template <class Region, class Sink>
void markRayCulled(const VoxelGrid& grid, const Point3f& origin, const RayEnd& ray,
                   const Region& region, BackwardScratch& scratch, Sink& update, MarkCounts& counts,
                   const VoxelKey* origin_key = nullptr) {
  markCrossedCulled(grid, origin, ray, region, scratch, update, counts, origin_key);
  markEnd(ray, update, counts);
}

/// markRayCulled for rays[id], `ids`, through a SharedFrameSink, each backward walk queued
/// when it can be (the fast walk, prepareBackward's kFast, between two voxels of the box): the
/// end voxel is marked now, the walk by the sink's DenseMarks::markQueuedBack (with `region`'s
/// frame masks), which the caller runs before the marks are read — and a walk it hands over (a
/// near-tie on the way) the caller walks again by markCrossedCulled (the walk's id is its ray's
/// index; its end is marked). Other rays are marked as markRayCulled does. Returns how many walks
/// were queued.
template <class Region>
std::size_t markRaysCulledQueued(const VoxelGrid& grid, const Point3f& origin, const RayEnd* rays,
                                 std::span<const std::uint32_t> ids, const Region& region,
                                 BackwardScratch& scratch, SharedFrameSink& sink,
                                 MarkCounts& counts, const VoxelKey& origin_key) {
  std::size_t queued = 0;
  startRaysByEight(
      grid, origin, origin_key, rays, ids,
      [&](std::uint32_t id, const TraversalStarts& st, int l) {
        const RayEnd& ray = rays[id];
        if (st.kind[l] == TraversalKind::kRay) {
          if (st.end[l] != TraversalEnd::kClean) {
            markRayCulled(grid, origin, ray, region, scratch, sink, counts, &origin_key);
            return;
          }
          BackwardWalk walk;
          walk.s = st.start[l];
          fastBackwardFrom(st.crossings[l], st.times[l], walk);
          const TraversalStart& s = walk.s;
          const int delta[3] = {-s.step[0], -s.step[1], -s.step[2]};
          if (!sink.dense.queueBackWalk(s.end, delta, s.origin, walk.head, s.t_delta, walk.next,
                                        walk.bound, walk.total, id)) {
            markRayCulled(grid, origin, ray, region, scratch, sink, counts, &origin_key);
            return;
          }
          ++queued;
        }
        markEnd(ray, sink, counts);  // (one voxel: nothing crossed)
      },
      [&](std::uint32_t id) {
        markRayCulled(grid, origin, rays[id], region, scratch, sink, counts, &origin_key);
      });
  return queued;
}

}  // namespace densemap
