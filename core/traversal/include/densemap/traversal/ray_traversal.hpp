#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <type_traits>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"

namespace densemap {

/// The state OctoMap 1.9.7's `OcTreeBaseImpl::computeRayKeys(origin, end)` starts its loop
/// with. The arithmetic is copied operation for operation (float direction and length, double
/// tMax/tDelta, the `(float)` half step) because a different but "more correct" rounding would
/// visit different voxels on boundary cases.
struct TraversalStart {
  VoxelKey origin;
  VoxelKey end;
  float length = 0.0F;
  int step[3] = {0, 0, 0};
  double t_max[3] = {0, 0, 0};
  double t_delta[3] = {0, 0, 0};
};

enum class TraversalKind { kInvalid, kSameVoxel, kRay };

/// startTraversal (below) with the ends' keys given (grid.pointToKey of origin and end, both in
/// range, so never kInvalid): a scan's rays share the origin's, and a ray's end key is known
/// before it is walked.
inline TraversalKind startTraversal(const VoxelGrid& grid, const Point3f& origin,
                                    const VoxelKey& key_origin, const Point3f& end,
                                    const VoxelKey& key_end, TraversalStart& start) {
  if (key_origin == key_end) return TraversalKind::kSameVoxel;
  start.origin = key_origin;
  start.end = key_end;

  // Vector3 arithmetic of OctoMap, one float operation at a time.
  float dir[3] = {end.x() - origin.x(), end.y() - origin.y(), end.z() - origin.z()};
  const float norm_sq = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
  start.length = static_cast<float>(std::sqrt(static_cast<double>(norm_sq)));
  // Two voxels but no length: a ray shorter than ~1e-19 m across a border (its float squared
  // length underflows to 0). OctoMap then divides by zero and loops forever (steps of tDelta 0);
  // it has no voxel to visit, as a ray inside one voxel.
  if (!(start.length > 0.0F)) return TraversalKind::kSameVoxel;
  for (float& d : dir) d /= start.length;

  const double resolution = grid.resolution();
  // (The key's coordinates as an array: VoxelKey's operator[] is a branch chain in a loop.)
  const std::uint16_t origin_coord[3] = {key_origin.x, key_origin.y, key_origin.z};
#pragma GCC unroll 3  // the axes in registers (unrolled loops are -O3's, not -O2's)
  for (int i = 0; i < 3; ++i) {
    start.step[i] = dir[i] > 0.0F ? 1 : (dir[i] < 0.0F ? -1 : 0);
    if (start.step[i] != 0) {
      double voxel_border = grid.keyToCoord(origin_coord[i]);
      voxel_border += static_cast<float>(start.step[i] * resolution * 0.5);
      start.t_max[i] =
          (voxel_border - static_cast<double>(origin[i])) / static_cast<double>(dir[i]);
      start.t_delta[i] = resolution / static_cast<double>(std::fabs(dir[i]));
    } else {
      start.t_max[i] = std::numeric_limits<double>::max();
      start.t_delta[i] = std::numeric_limits<double>::max();
    }
  }
  return TraversalKind::kRay;
}

/// A ray's ends' keys (grid.pointToKey of its origin and end, both in range).
struct RayKeys {
  VoxelKey origin;
  VoxelKey end;
};

/// kInvalid: origin or end outside the addressable range (nothing is visited);
/// kSameVoxel: both in one voxel (nothing is visited); kRay: `start` is filled.
inline TraversalKind startTraversal(const VoxelGrid& grid, const Point3f& origin,
                                    const Point3f& end, TraversalStart& start) {
  const auto key_origin = grid.pointToKey(origin);
  const auto key_end = grid.pointToKey(end);
  if (!key_origin || !key_end) return TraversalKind::kInvalid;
  return startTraversal(grid, origin, *key_origin, end, *key_end, start);
}

/// How traverseRay's loop from `s` ends (see endOf).
enum class TraversalEnd {
  kIrregular,  // the keys' differences disagree with the steps' signs: no count of crossings
  kUnsure,     // it may stop by the length test, or the crossing counts are decided by near-ties
  kClean,      // by entering the end voxel after exactly crossings[0..2] crossings per axis
};

/// endOf's times (see there).
struct TraversalEndTimes {
  double last[3];
  double scale;
};

/// How traverseRay's loop from `s` ends, decided with margins; fills `crossings` (per axis, the
/// borders between the origin's and the end's voxel). kClean: the loop's crossings are, in
/// time order (each axis' times accumulated by repeated addition, ties to the higher axis), the
/// first crossings[a] of each axis — the last of them (the end voxel's entry) before the first
/// one beyond them and within the ray's length — so the loop enters the end voxel at its
/// (crossings[0] + crossings[1] + crossings[2])-th step and stops there. Each decision must win
/// by more than one bound on the rounding of two times: an accumulated sum is within
/// (k + 8) * 2^-50 * (|t| + |t0|) of t0 + k * delta, below 2 (total + 8) 2^-50 scale (scale: the
/// largest time involved, plus a step); near-ties among the axes' last or first-beyond
/// crossings are kUnsure too (the backward walk's first decisions).
/// `times`, when given and the end is kClean: each axis' last crossing time (-inf for none) and
/// the scale, for the backward walk's start.
inline TraversalEnd endOf(const TraversalStart& s, int (&crossings)[3],
                          TraversalEndTimes* times = nullptr) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double last[3], beyond[3];  // per axis: the last crossing's time, the next one's
  double scale = 0;
  int total = 0;
  // The keys' coordinates as ints (VoxelKey's operator[] is a branch chain in a loop).
  const int key_end[3] = {s.end.x, s.end.y, s.end.z};
  const int key_origin[3] = {s.origin.x, s.origin.y, s.origin.z};
#pragma GCC unroll 3  // as in startTraversal
  for (int a = 0; a < 3; ++a) {
    const int c = (key_end[a] - key_origin[a]) * s.step[a];
    crossings[a] = c;
    if (s.step[a] == 0) {
      if (key_end[a] != key_origin[a]) return TraversalEnd::kIrregular;
      last[a] = -kInf;
      beyond[a] = kInf;
      continue;
    }
    if (c < 0) return TraversalEnd::kIrregular;
    total += c;
    beyond[a] = s.t_max[a] + c * s.t_delta[a];
    last[a] = c > 0 ? s.t_max[a] + (c - 1) * s.t_delta[a] : -kInf;
    scale = std::max(scale, std::fabs(s.t_max[a]) + (c + 1) * s.t_delta[a]);
  }
  const double bound = 4 * (total + 8) * 0x1p-50 * scale;
  // (inf - inf is NaN: never near.)
  const auto near = [bound](double x, double y) { return std::fabs(x - y) <= bound; };
  if (near(last[0], last[1]) || near(last[0], last[2]) || near(last[1], last[2]) ||
      near(beyond[0], beyond[1]) || near(beyond[0], beyond[2]) || near(beyond[1], beyond[2])) {
    return TraversalEnd::kUnsure;
  }
  const double last_max = std::max(std::max(last[0], last[1]), last[2]);
  const double beyond_min = std::min(std::min(beyond[0], beyond[1]), beyond[2]);
  if (!(last_max > -kInf) || !(beyond_min - last_max > bound) ||
      !(static_cast<double>(s.length) - last_max > bound)) {
    return TraversalEnd::kUnsure;
  }
  if (times != nullptr) {
    for (int a = 0; a < 3; ++a) times->last[a] = last[a];
    times->scale = scale;
  }
  return TraversalEnd::kClean;
}

/// traverseRay's step visitors count a ray's steps from this many (endOf's test costs about as
/// much as the end tests of a few steps).
inline constexpr int kCountedStepsFrom = 8;

/// startTraversal and endOf (with its times) of up to eight rays from one origin.
struct TraversalStarts {
  TraversalKind kind[8];
  TraversalStart start[8];     // kind kRay
  TraversalEnd end[8];         // kind kRay: endOf's
  int crossings[8][3];         // kind kRay: endOf's
  TraversalEndTimes times[8];  // end kClean
};
/// startTraversals' values for eight rays as its lanes hold them, side by side (lane i: ray i;
/// lanes from n on copy ray 0): startTraversal's times, steps and length, endOf's crossings
/// and last crossing times, and per lane bits. Lane i's kind is kSameVoxel when `same` or not
/// `has_length` names it, else kRay; then its end is kIrregular when `irregular` names it, else
/// kUnsure when `unsure` does, else kClean, and `last` and `scale` are endOf's
/// TraversalEndTimes (`crossings`, endOf's, are exact unless kIrregular).
template <class Int>
struct TraversalLaneValues {
  alignas(64) double tm[3][8], td[3][8], la[3][8], sc[8];  // t_max, t_delta, last, scale
  alignas(64) Int st[3][8], cr[3][8];                      // step, crossings
  alignas(32) float len[8];
  unsigned same = 0, has_length = 0, irregular = 0, unsure = 0;
};
/// TraversalLaneValues in 32-bit ints (the AVX2 lanes'), with the rays' end keys.
struct TraversalLanes : TraversalLaneValues<std::int32_t> {
  alignas(32) std::int32_t key_end[3][8];
};
/// startTraversals into lanes (`out`), for a caller that reads them side by side: the same
/// values bit for bit, with AVX-512 when `wide` and the processor has it (hasWideLanes), else
/// with AVX2 where it has that (hasFourLanes); without either, every lane is told kRay with a
/// kIrregular end (the caller walks them by traverseRay).
void startTraversalLanes(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& key_origin,
                         const Point3f* ends, const VoxelKey* key_ends, int n, TraversalLanes& out,
                         bool wide = true);
/// Fills `out` for rays 0..n-1 (n <= 8) from `origin` (key `key_origin`) to `ends[i]` (key
/// `key_ends[i]`; both in range): bit for bit what startTraversal and endOf give, eight rays
/// side by side in AVX-512 lanes when `wide` and the processor has them (hasWideLanes), else in
/// AVX2 lanes (the doubles four at a time) when it has those (hasFourLanes), else one by one
/// with those functions.
void startTraversals(const VoxelGrid& grid, const Point3f& origin, const VoxelKey& key_origin,
                     const Point3f* ends, const VoxelKey* key_ends, int n, TraversalStarts& out,
                     bool wide = true);
/// The widest lanes the environment allows: DENSEMAP_LANES=256 keeps every kernel to AVX2
/// lanes, =0 to one value at a time (to compare the paths on one machine, or to step around
/// a processor's fault); unset or any other value, 512. Read once.
[[nodiscard]] int laneCap();
/// Whether the processor (and the system) has the AVX-512 lanes the wide walks and starts use
/// (AVX-512 F, VL and DQ; checked once) and laneCap() allows them.
[[nodiscard]] bool hasWideLanes();
/// Whether the processor has AVX2 (the four-lane kernels') and laneCap() allows it, checked
/// once.
[[nodiscard]] bool hasFourLanes();

/// The voxels of a ray's traversal when traverseRay's step visitors walk it counted (at least
/// kCountedStepsFrom crossings and endOf kClean: the origin's voxel, then countedSteps' total - 1
/// steps), else 0 (the loop with end tests). The one rule for both traverseRay and the walks
/// queued by a caller (DenseMarks::queueWalk).
[[nodiscard]] inline int countedTotal(const TraversalStart& s) {
  const int total = std::abs(s.end.x - s.origin.x) + std::abs(s.end.y - s.origin.y) +
                    std::abs(s.end.z - s.origin.z);
  if (total < kCountedStepsFrom) return 0;
  int crossings[3];
  return endOf(s, crossings) == TraversalEnd::kClean ? total : 0;
}
/// countedTotal from endOf's answer (`end`, `crossings`) when the caller has it: for a kClean
/// end the crossings are the keys' distances.
[[nodiscard]] inline int countedTotal(TraversalEnd end, const int (&crossings)[3]) {
  if (end != TraversalEnd::kClean) return 0;
  const int total = crossings[0] + crossings[1] + crossings[2];
  return total >= kCountedStepsFrom ? total : 0;
}

/// The steps of a clean ray's loop (endOf: it enters the end voxel after exactly `total`
/// crossings) before the end voxel: total - 1 of them, each crossing the border with the
/// smallest tMax, ties to the higher axis (traverseRay's choice), told to `steps` as
/// `steps.template step<AXIS>()`. Inlined, so that a `steps` held in the caller's locals stays
/// in registers.
template <class Steps>
[[gnu::always_inline]] inline void countedSteps(const TraversalStart& s, int total, Steps& steps) {
  double t0 = s.t_max[0], t1 = s.t_max[1], t2 = s.t_max[2];
  const double d0 = s.t_delta[0], d1 = s.t_delta[1], d2 = s.t_delta[2];
  for (int n = 1; n < total; ++n) {
    if (t0 < t1 && t0 < t2) {
      t0 += d0;
      steps.template step<0>();
    } else if (!(t0 < t1) && t1 < t2) {
      t1 += d1;
      steps.template step<1>();
    } else {
      t2 += d2;
      steps.template step<2>();
    }
  }
}

namespace detail {

/// Steps to a step visitor (step<AXIS>(new coordinate), returning R): the key followed.
template <class Visitor, class R = void>
struct KeyedSteps {
  Visitor& visit;
  int key[3];
  int step_by[3];
  template <int A>
  R step() {
    key[A] = (key[A] + step_by[A]) & 0xffff;  // OctoMap's uint16 key arithmetic
    if constexpr (std::is_void_v<R>) {
      visit.template step<A>(key[A]);
    } else {
      return visit.template step<A>(key[A]);
    }
  }
};

/// Steps to a key visitor (bool(const VoxelKey&)): the key followed and visited.
template <class Visitor>
struct KeyVisits {
  Visitor& visit;
  int key[3];
  int step_by[3];
  template <int A>
  bool step() {
    key[A] = (key[A] + step_by[A]) & 0xffff;
    return visit(VoxelKey{static_cast<std::uint16_t>(key[0]), static_cast<std::uint16_t>(key[1]),
                          static_cast<std::uint16_t>(key[2])});
  }
};

}  // namespace detail

/// Visits the voxels that OctoMap 1.9.7's `OcTreeBaseImpl::computeRayKeys(origin, end)` returns,
/// in the same order: the origin's voxel first, the end point's voxel excluded.
/// (Amanatides & Woo, "A Fast Voxel Traversal Algorithm for Ray Tracing", 1987.)
///
/// Returns false (visiting nothing) when origin or end lies outside the addressable range.
/// `visit(const VoxelKey&)` is called once per voxel. Thread-safe (pure).
/// `keys`, when given, are the ends' keys (RayKeys), not computed again.
template <class Visitor>
bool traverseRay(const VoxelGrid& grid, const Point3f& origin, const Point3f& end, Visitor&& visit,
                 const RayKeys* keys = nullptr) {
  TraversalStart s;
  const TraversalKind kind = keys != nullptr
                                 ? startTraversal(grid, origin, keys->origin, end, keys->end, s)
                                 : startTraversal(grid, origin, end, s);
  if (kind != TraversalKind::kRay) return kind == TraversalKind::kSameVoxel;
  // A visitor that follows the steps is told the start (begin(origin key, steps), first())
  // and then which axis moved (step<AXIS>(new coordinate)) instead of each key.
  constexpr bool kSteps = requires { visit.template step<0>(0); };
  // Each step crosses the border with the smallest tMax, ties to the higher axis. The key lives
  // in three registers (updating one 16-bit field of a VoxelKey in memory and comparing the
  // whole key is slower).
  int key[3] = {s.origin.x, s.origin.y, s.origin.z};
  const int last[3] = {s.end.x, s.end.y, s.end.z};
  if constexpr (kSteps) {
    // A long ray whose loop ends cleanly (endOf) takes a known number of steps: no end test
    // per step (the key's three comparisons and the length test).
    const int total = countedTotal(s);
    const bool counted = total != 0;
    // A visitor with fastSteps(first voxel, steps, last voxel) may hand the counted loop a value
    // of its own steps in place of begin() (kept in registers: first(), step<AXIS>()), taken
    // back by endFastSteps(steps).
    if constexpr (requires { visit.fastSteps(s.origin, s.step, s.end); }) {
      if (counted) {
        if (auto steps = visit.fastSteps(s.origin, s.step, s.end)) {
          steps->first();
          countedSteps(s, total, *steps);
          visit.endFastSteps(*steps);
          return true;
        }
      }
    }
    visit.begin(s.origin, s.step);
    visit.first();
    if (counted) {
      detail::KeyedSteps<Visitor> keyed{
          visit, {key[0], key[1], key[2]}, {s.step[0], s.step[1], s.step[2]}};
      countedSteps(s, total, keyed);
      return true;
    }
  } else {
    visit(s.origin);
  }
  double t0 = s.t_max[0], t1 = s.t_max[1], t2 = s.t_max[2];
  const double length = static_cast<double>(s.length);
  while (true) {
    int axis;
    if (t0 < t1) {
      if (t0 < t2) {
        key[0] = (key[0] + s.step[0]) & 0xffff;  // OctoMap's uint16 key arithmetic
        t0 += s.t_delta[0];
        axis = 0;
      } else {
        key[2] = (key[2] + s.step[2]) & 0xffff;
        t2 += s.t_delta[2];
        axis = 2;
      }
    } else if (t1 < t2) {
      key[1] = (key[1] + s.step[1]) & 0xffff;
      t1 += s.t_delta[1];
      axis = 1;
    } else {
      key[2] = (key[2] + s.step[2]) & 0xffff;
      t2 += s.t_delta[2];
      axis = 2;
    }
    if (key[0] == last[0] && key[1] == last[1] && key[2] == last[2]) break;
    // Accumulated rounding can step past the end voxel without entering it; OctoMap stops
    // once the travelled distance exceeds the ray length.
    if (std::min(std::min(t0, t1), t2) > length) break;
    if constexpr (kSteps) {
      if (axis == 0) {
        visit.template step<0>(key[0]);
      } else if (axis == 1) {
        visit.template step<1>(key[1]);
      } else {
        visit.template step<2>(key[2]);
      }
    } else {
      (void)axis;
      visit(VoxelKey{static_cast<std::uint16_t>(key[0]), static_cast<std::uint16_t>(key[1]),
                     static_cast<std::uint16_t>(key[2])});
    }
  }
  return true;
}

/// Convenience form returning the keys (tests, tools); hot paths use the visitor form.
[[nodiscard]] inline bool computeRayKeys(const VoxelGrid& grid, const Point3f& origin,
                                         const Point3f& end, std::vector<VoxelKey>& keys) {
  keys.clear();
  return traverseRay(grid, origin, end, [&keys](const VoxelKey& k) { keys.push_back(k); });
}

}  // namespace densemap
