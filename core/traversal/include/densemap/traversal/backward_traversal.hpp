#pragma once

// A ray's traversal walked backward, from its end toward its origin (the culling region's
// walks stop where the region begins): the same voxels as traverseRay, in reverse order.
#include <cstddef>
#include <vector>

#include "densemap/traversal/ray_traversal.hpp"

namespace densemap {

/// Buffers reused by traverseRayBackward.
struct BackwardScratch {
  std::vector<double> times[3];
  std::vector<VoxelKey> keys;
};

namespace detail {

/// The exact backward walk (see traverseRayBackward); the first `skip` voxels are not visited
/// again (the fast walk already did). Returns the forward traversal's voxel count.
template <class Visitor>
std::size_t backwardExact(const VoxelGrid& grid, const Point3f& origin, const Point3f& end,
                          const TraversalStart& s, const int crossings[3], bool regular,
                          BackwardScratch& scratch, std::size_t skip, Visitor&& visit) {
  if (regular) {
    // times[a][k]: tMax of axis a after k of its crossings; k = crossings[a] is the exit.
    for (int a = 0; a < 3; ++a) {
      if (s.step[a] == 0) continue;
      auto& t = scratch.times[a];
      const auto needed = static_cast<std::size_t>(crossings[a]) + 1;
      if (t.size() < needed) t.resize(std::max(needed, 2 * t.size()));  // grow only
      double* out = t.data();
      double v = s.t_max[a];
      for (int k = 0; k <= crossings[a]; ++k) {
        out[k] = v;
        v += s.t_delta[a];
      }
    }
    // Forward order: (time, higher axis first). The last entry crossing must precede the first
    // exit crossing and lie within the ray's length.
    int last_axis = -1;
    double last_time = 0;
    int exit_axis = -1;
    double exit_time = 0;
    for (int a = 0; a < 3; ++a) {
      if (s.step[a] == 0) continue;
      const auto& t = scratch.times[a];
      if (crossings[a] > 0) {
        const double v = t[crossings[a] - 1];
        if (last_axis < 0 || v > last_time || (v == last_time && a < last_axis)) {
          last_axis = a;
          last_time = v;
        }
      }
      const double x = t[crossings[a]];
      if (exit_axis < 0 || x < exit_time || (x == exit_time && a > exit_axis)) {
        exit_axis = a;
        exit_time = x;
      }
    }
    const bool before_exit =
        exit_axis < 0 || last_time < exit_time || (last_time == exit_time && last_axis > exit_axis);
    if (last_axis >= 0 && before_exit && last_time <= static_cast<double>(s.length)) {
      constexpr double kNone = -std::numeric_limits<double>::infinity();
      int next[3] = {crossings[0] - 1, crossings[1] - 1, crossings[2] - 1};
      const double* times[3] = {scratch.times[0].data(), scratch.times[1].data(),
                                scratch.times[2].data()};
      double head[3];
      for (int a = 0; a < 3; ++a) {
        head[a] = s.step[a] != 0 && next[a] >= 0 ? times[a][next[a]] : kNone;
      }
      const std::size_t total =
          static_cast<std::size_t>(crossings[0] + crossings[1] + crossings[2]);
      VoxelKey current = s.end;
      for (std::size_t done = 0; done < total; ++done) {
        // The latest crossing; ties stay with the lower axis.
        int dim = head[0] >= head[1] ? 0 : 1;
        if (head[2] > head[dim]) dim = 2;
        --next[dim];
        head[dim] = next[dim] >= 0 ? times[dim][next[dim]] : kNone;
        current[dim] = static_cast<std::uint16_t>(current[dim] - s.step[dim]);
        if (done >= skip && !visit(current)) break;
      }
      return total;
    }
  }
  auto& keys = scratch.keys;
  keys.clear();
  traverseRay(grid, origin, end, [&keys](const VoxelKey& k) { keys.push_back(k); });
  std::size_t done = 0;
  for (auto it = keys.rbegin(); it != keys.rend(); ++it, ++done) {
    if (done >= skip && !visit(*it)) break;
  }
  return keys.size();
}

}  // namespace detail

/// A ray's backward walk in progress (see traverseRayBackward): the forward start, the
/// crossings per axis, and for the fast path the next crossing time to undo per axis.
struct BackwardWalk {
  TraversalStart s;
  int crossings[3] = {0, 0, 0};
  double head[3] = {0, 0, 0};
  int next[3] = {0, 0, 0};
  double bound = 0;       // decisions must win by more than this
  std::size_t total = 0;  // voxels of the forward traversal
};

enum class BackwardMode {
  kNothing,         // no voxels (origin or end outside the range, or both in one voxel)
  kExactIrregular,  // replay the recorded forward traversal
  kExact,           // the exact accumulated walk
  kFast,            // `walk` is ready for fast steps
};

/// The fast backward walk's heads, counts and bound from a kClean endOf (its crossings and
/// times); walk.s must be the ray's start already.
inline void fastBackwardFrom(const int (&crossings)[3], const TraversalEndTimes& times,
                             BackwardWalk& walk) {
  // One bound for the whole walk: heads are computed t0 + k * delta (the last crossings' times,
  // -inf for an axis with none), then decremented.
  constexpr double kRel = 0x1p-50;
  walk.total = static_cast<std::size_t>(crossings[0] + crossings[1] + crossings[2]);
  walk.bound = 2 * (static_cast<double>(walk.total) + 16) * kRel * times.scale;
  for (int a = 0; a < 3; ++a) {
    walk.crossings[a] = crossings[a];
    walk.next[a] = crossings[a] - 1;
    walk.head[a] = times.last[a];
  }
}

/// Sets up the backward walk of ray (origin, end); decides with margins whether the fast path
/// may start (see traverseRayBackward).
/// (`keys`, when given: the ends' keys, as startTraversal takes them.)
inline BackwardMode prepareBackward(const VoxelGrid& grid, const Point3f& origin,
                                    const Point3f& end, BackwardWalk& walk,
                                    const RayKeys* keys = nullptr) {
  TraversalStart& s = walk.s;
  const TraversalKind kind = keys != nullptr
                                 ? startTraversal(grid, origin, keys->origin, end, keys->end, s)
                                 : startTraversal(grid, origin, end, s);
  if (kind != TraversalKind::kRay) return BackwardMode::kNothing;
  int(&crossings)[3] = walk.crossings;
  // Termination as in backwardExact, decided with margins.
  TraversalEndTimes times;
  switch (endOf(s, crossings, &times)) {
    case TraversalEnd::kIrregular:
      return BackwardMode::kExactIrregular;
    case TraversalEnd::kUnsure:
      return BackwardMode::kExact;
    case TraversalEnd::kClean:
      break;
  }
  fastBackwardFrom(crossings, times, walk);
  return BackwardMode::kFast;
}

namespace detail {

/// traverseRayBackward's fast loop from `walk` (kFast): steps.template step<AXIS>() per step
/// (false: stop). Returns the steps taken; `handover` is set when a decision did not win by the
/// bound (the exact walk goes on from there). Inlined, so that a `steps` held in the caller's
/// locals stays in registers; heads and counts are locals with one branch per axis, as in
/// traverseRay (stepping through `walk` in memory, branch-free, is much slower).
template <class Steps>
[[gnu::always_inline]] inline std::size_t backwardSteps(const BackwardWalk& walk, Steps& steps,
                                                        bool& handover) {
  constexpr double kNone = -std::numeric_limits<double>::infinity();
  const double bound = walk.bound;
  const double d0 = walk.s.t_delta[0], d1 = walk.s.t_delta[1], d2 = walk.s.t_delta[2];
  double h0 = walk.head[0], h1 = walk.head[1], h2 = walk.head[2];
  int n0 = walk.next[0], n1 = walk.next[1], n2 = walk.next[2];
  // The runner-up is known in each branch: the other of h0, h1 for axis 2, and the larger of
  // the two others for axes 0 and 1.
  for (std::size_t done = 0; done < walk.total; ++done) {
    const double high01 = std::max(h0, h1);
    if (h2 > high01) {
      if (!(h2 - high01 > bound)) {
        handover = true;
        return done;
      }
      h2 = --n2 >= 0 ? h2 - d2 : kNone;
      if (!steps.template step<2>()) return done + 1;
    } else if (h0 >= h1) {
      if (!(h0 - std::max(h1, h2) > bound)) {
        handover = true;
        return done;
      }
      h0 = --n0 >= 0 ? h0 - d0 : kNone;
      if (!steps.template step<0>()) return done + 1;
    } else {
      if (!(h1 - std::max(h0, h2) > bound)) {
        handover = true;
        return done;
      }
      h1 = --n1 >= 0 ? h1 - d1 : kNone;
      if (!steps.template step<1>()) return done + 1;
    }
  }
  return walk.total;
}

}  // namespace detail

/// Visits the voxels traverseRay(origin, end) visits in reverse order — end side first, the
/// origin's voxel last — for as long as `visit(key)` returns true. Returns how many voxels the
/// forward traversal has (visited or not).
///
/// Exact without replaying the forward loop: traverseRay takes the border crossings of the
/// three axes in the order of their times (each axis' times accumulated by repeated addition,
/// ties to the higher axis) — a merge of three sorted lists. So the crossing that entered a
/// voxel is the latest of the axes' last crossings (ties to the lower axis), and walking back
/// from the end voxel undoes crossings in exactly reverse order.
/// Fast path: crossing times are computed directly (t0 + k * delta) and every decision must win
/// by more than the bound on the accumulated sum's rounding (k + 8) * 2^-50 * |t|; the first
/// decision that does not (near-ties: rays through edges and corners) hands over to the exact
/// walk, which accumulates the times as traverseRay does. When the forward loop would not end by
/// entering the end voxel (an end within rounding of a border: OctoMap's `dist > length` stop),
/// the forward traversal is recorded and replayed backwards.
/// `keys`, when given, are the ends' keys (RayKeys), not computed again.
template <class Visitor>
std::size_t traverseRayBackward(const VoxelGrid& grid, const Point3f& origin, const Point3f& end,
                                BackwardScratch& scratch, Visitor&& visit,
                                const RayKeys* keys = nullptr) {
  BackwardWalk walk;
  const BackwardMode mode = prepareBackward(grid, origin, end, walk, keys);
  if (mode == BackwardMode::kNothing) return 0;
  if (mode != BackwardMode::kFast) {
    return detail::backwardExact(grid, origin, end, walk.s, walk.crossings,
                                 mode == BackwardMode::kExact, scratch, 0, visit);
  }
  // Each fast step undoes the latest crossing (ties to the lower axis) if it beats the runner-up
  // (-inf when an axis has none left) by the bound; else the exact walk takes over (from the
  // step it did not take). A visitor that follows the steps (begin(end key, deltas),
  // step<AXIS>(new coordinate)) is told which axis moved instead of the new key, or hands the
  // loop a value of its own steps in place of begin() (fastSteps(first voxel, deltas, last
  // voxel): kept in registers, taken back by endFastSteps); the exact walk calls it with keys.
  constexpr bool kSteps = requires { visit.template step<0>(0); };
  const TraversalStart& s = walk.s;
  const int delta[3] = {-s.step[0], -s.step[1], -s.step[2]};
  std::size_t done = 0;
  bool handover = false;
  bool ran = false;
  if constexpr (requires { visit.fastSteps(s.end, delta, s.origin); }) {
    if (auto steps = visit.fastSteps(s.end, delta, s.origin)) {
      done = detail::backwardSteps(walk, *steps, handover);
      visit.endFastSteps(*steps);
      ran = true;
    }
  }
  if (!ran) {
    if constexpr (kSteps) {
      visit.begin(s.end, delta);
      detail::KeyedSteps<Visitor, bool> keyed{
          visit, {s.end[0], s.end[1], s.end[2]}, {delta[0], delta[1], delta[2]}};
      done = detail::backwardSteps(walk, keyed, handover);
    } else {
      detail::KeyVisits<Visitor> keyed{
          visit, {s.end[0], s.end[1], s.end[2]}, {delta[0], delta[1], delta[2]}};
      done = detail::backwardSteps(walk, keyed, handover);
    }
  }
  if (handover) {
    return detail::backwardExact(grid, origin, end, s, walk.crossings, true, scratch, done, visit);
  }
  return walk.total;
}

}  // namespace densemap
