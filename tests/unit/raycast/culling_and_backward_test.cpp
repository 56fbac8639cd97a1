// The two building blocks of culling: the backward traversal (exactly traverseRay reversed)
// and the culling region (exactly Alg. 3's fixed point, grown by breadth-first search).
#include <gtest/gtest.h>

#include <algorithm>
#include <deque>
#include <iostream>
#include <optional>
#include <random>
#include <set>

#include "densemap/traversal/backward_traversal.hpp"
#include "densemap/traversal/ray_traversal.hpp"
#include "densemap/traversal/dense_marks.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/raycast/culling_region.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/raycast/ray_marking.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

/// An update set's cells (packed key, occupied), sorted: two sets mark the same cells iff equal.
std::vector<std::pair<std::uint64_t, bool>> markedCells(const ScanUpdate& update) {
  std::vector<std::pair<std::uint64_t, bool>> cells;
  update.forEachCell([&](const VoxelKey& k, const CellHits& h) {
    cells.emplace_back(k.packed(), h.occupied > 0);
  });
  std::sort(cells.begin(), cells.end());
  return cells;
}

TEST(TraverseRayBackward, IsTheForwardTraversalReversedOnAdversarialRays) {
  BackwardScratch scratch;
  std::size_t rays = 0, nonempty = 0;
  for (const double resolution : {0.05, 0.1, 0.15, 0.2, 1.0 / 3.0, 0.4}) {
    const VoxelGrid grid(resolution);
    test::RandomRays random(resolution, 12.0, 7);
    for (const test::RayKind kind : test::kAllRayKinds) {
      for (int i = 0; i < 4000; ++i) {
        const test::Ray ray = random.next(kind);
        std::vector<VoxelKey> forward, backward;
        ASSERT_TRUE(computeRayKeys(grid, ray.origin, ray.end, forward) || forward.empty());
        const std::size_t total =
            traverseRayBackward(grid, ray.origin, ray.end, scratch, [&](const VoxelKey& k) {
              backward.push_back(k);
              return true;
            });
        ASSERT_EQ(total, forward.size());
        std::reverse(backward.begin(), backward.end());
        ASSERT_EQ(backward, forward)
            << "resolution " << resolution << " kind " << static_cast<int>(kind) << " ray " << i;
        // Stopping early visits a prefix of the reversed traversal.
        if (forward.size() > 2) {
          std::size_t seen = 0;
          traverseRayBackward(grid, ray.origin, ray.end, scratch,
                              [&](const VoxelKey&) { return ++seen < 2; });
          EXPECT_EQ(seen, 2U);
        }
        ++rays;
        nonempty += forward.empty() ? 0 : 1;
      }
    }
  }
  EXPECT_GT(nonempty, rays / 2);
}

/// Follows a walk's steps (begin, first, step<A>) back to keys, as the step visitors of
/// traverseRay and traverseRayBackward are driven; keys from the exact backward walk come as
/// keys.
struct StepTracker {
  std::vector<VoxelKey>& keys;
  VoxelKey at{};
  int moves[3] = {0, 0, 0};
  void begin(const VoxelKey& k, const int (&delta)[3]) {
    at = k;
    for (int a = 0; a < 3; ++a) moves[a] = delta[a];
  }
  void first() { keys.push_back(at); }
  template <int A>
  bool step(int coord) {
    // The coordinate is the last one's moved by the walk's delta, in 16 bits.
    EXPECT_EQ(coord, (at[A] + moves[A]) & 0xffff);
    at[A] = static_cast<std::uint16_t>(coord);
    keys.push_back(at);
    return true;
  }
  bool operator()(const VoxelKey& k) {
    keys.push_back(k);
    return true;
  }
};

TEST(TraverseRay, StepVisitorsFollowTheKeysOfKeyVisitorsBothWays) {
  BackwardScratch scratch;
  std::size_t stepped = 0;
  for (const double resolution : {0.05, 0.2, 1.0 / 3.0}) {
    const VoxelGrid grid(resolution);
    test::RandomRays random(resolution, 12.0, 11);
    for (const test::RayKind kind : test::kAllRayKinds) {
      for (int i = 0; i < 2000; ++i) {
        const test::Ray ray = random.next(kind);
        std::vector<VoxelKey> forward, by_steps, backward_by_steps;
        const bool ok = computeRayKeys(grid, ray.origin, ray.end, forward);
        StepTracker tracker{by_steps};
        ASSERT_EQ(traverseRay(grid, ray.origin, ray.end, tracker), ok);
        ASSERT_EQ(by_steps, forward) << "forward, kind " << static_cast<int>(kind) << " ray " << i;
        StepTracker back{backward_by_steps};
        const auto keys = [&]() -> std::optional<RayKeys> {
          const auto o = grid.pointToKey(ray.origin);
          const auto e = grid.pointToKey(ray.end);
          if (!o || !e) return std::nullopt;
          return RayKeys{*o, *e};
        }();
        traverseRayBackward(grid, ray.origin, ray.end, scratch, back, keys ? &*keys : nullptr);
        std::reverse(backward_by_steps.begin(), backward_by_steps.end());
        ASSERT_EQ(backward_by_steps, forward)
            << "backward, kind " << static_cast<int>(kind) << " ray " << i;
        stepped += forward.size();
      }
    }
  }
  EXPECT_GT(stepped, 100000U);
}

TEST(DenseMarks, StepMarkerMarksAsTheHashOnWalksInsideAndLeavingItsBox) {
  const VoxelGrid grid(0.2);
  test::RandomRays random(0.2, 12.0, 13);
  DenseMarks dense;
  for (int round = 0; round < 3; ++round) {
    // A box around the origin's side of the rays: many walks leave it, some start outside.
    const VoxelKey lo = *grid.pointToKey(Point3f(-6.0F, -5.0F, -4.0F));
    const VoxelKey hi = *grid.pointToKey(Point3f(5.0F, 6.0F, 3.0F));
    ASSERT_TRUE(dense.reset(lo, hi, 1U << 20));
    ScanUpdate plain, sut;
    DenseSink sink{dense, sut};
    MarkCounts plain_counts, sut_counts;
    for (int i = 0; i < 3000; ++i) {
      const test::Ray ray = random.next(test::kAllRayKinds[i % 8]);
      const RayEnd end = rayEndFor(grid, ray.origin, ray.end, 8.0);
      markRay(grid, ray.origin, end, plain, plain_counts);
      // Every other ray with its origin's key given (the integrator's call).
      const auto origin_key = grid.pointToKey(ray.origin);
      markRay(grid, ray.origin, end, sink, sut_counts,
              i % 2 == 0 && origin_key ? &*origin_key : nullptr);
    }
    dense.flushInto(sut);
    ASSERT_EQ(sut_counts.visits, plain_counts.visits);
    EXPECT_GT(plain.freeCount(), 10000U);
    EXPECT_EQ(sut.freeCount(), plain.freeCount()) << "round " << round;
    EXPECT_EQ(markedCells(plain), markedCells(sut)) << "round " << round;
  }
}

// startTraversals (eight rays side by side where the processor has AVX-512 or AVX2) and
// startTraversalLanes (AVX-512 or AVX2 lanes) give what startTraversal and endOf give, bit for
// bit, on adversarial rays from one origin per batch.
TEST(TraverseRay, WideStartsAreTheScalarStartsBitForBit) {
  std::size_t rays = 0, clean = 0;
  for (const double resolution : {0.05, 0.1, 0.2, 0.25, 1.0 / 3.0}) {
    const VoxelGrid grid(resolution);
    test::RandomRays random(resolution, 30.0, 23);
    for (int batch = 0; batch < 3000; ++batch) {
      const test::Ray first = random.next(test::kAllRayKinds[batch % 8]);
      const auto key_origin = grid.pointToKey(first.origin);
      if (!key_origin) continue;
      Point3f ends[8];
      VoxelKey keys[8];
      int n = 0;
      for (int i = 0; i < 8; ++i) {
        const test::Ray r = i == 0 ? first : random.next(test::kAllRayKinds[(batch + i) % 8]);
        const auto k = grid.pointToKey(r.end);
        if (!k) continue;
        ends[n] = r.end;
        keys[n++] = *k;
      }
      TraversalStarts wide, one;
      startTraversals(grid, first.origin, *key_origin, ends, keys, n, wide, true);
      startTraversals(grid, first.origin, *key_origin, ends, keys, n, one, false);
      TraversalLanes both[2];  // (AVX-512 lanes where the processor has them, AVX2 lanes)
      startTraversalLanes(grid, first.origin, *key_origin, ends, keys, n, both[0], true);
      startTraversalLanes(grid, first.origin, *key_origin, ends, keys, n, both[1], false);
      for (int i = 0; i < n; ++i) {
        ++rays;
        TraversalStart s;
        const TraversalKind kind =
            startTraversal(grid, first.origin, *key_origin, ends[i], keys[i], s);
        ASSERT_EQ(one.kind[i], kind);
        ASSERT_EQ(wide.kind[i], kind) << "batch " << batch << " ray " << i;
        const unsigned bit = 1U << i;
        for (const TraversalLanes& lanes : both) {
          const bool lane_ray = (lanes.same & bit) == 0 && (lanes.has_length & bit) != 0;
          ASSERT_EQ(lane_ray, kind == TraversalKind::kRay) << "batch " << batch << " ray " << i;
        }
        if (kind != TraversalKind::kRay) continue;
        int crossings[3];
        TraversalEndTimes times{};
        const TraversalEnd end = endOf(s, crossings, &times);
        ASSERT_EQ(wide.end[i], end) << "batch " << batch << " ray " << i;
        for (const TraversalLanes& lanes : both) {
          if (hasFourLanes()) {
            const TraversalEnd lane_end = (lanes.irregular & bit) != 0 ? TraversalEnd::kIrregular
                                          : (lanes.unsure & bit) != 0  ? TraversalEnd::kUnsure
                                                                       : TraversalEnd::kClean;
            ASSERT_EQ(lane_end, end) << "batch " << batch << " ray " << i;
            for (int a = 0; a < 3; ++a) {
              ASSERT_EQ(lanes.key_end[a][i], keys[i][a]);
              ASSERT_EQ(lanes.st[a][i], s.step[a]);
              ASSERT_EQ(lanes.tm[a][i], s.t_max[a]);
              ASSERT_EQ(lanes.td[a][i], s.t_delta[a]);
              if (end != TraversalEnd::kIrregular) {
                ASSERT_EQ(lanes.cr[a][i], crossings[a]);
              }
              if (end == TraversalEnd::kClean) {
                ASSERT_EQ(lanes.la[a][i], times.last[a]);
              }
            }
            if (end == TraversalEnd::kClean) {
              ASSERT_EQ(lanes.sc[i], times.scale);
            }
          } else {
            ASSERT_NE(lanes.irregular & bit, 0U);  // (walked by traverseRay)
          }
        }
        ASSERT_EQ(wide.start[i].length, s.length);
        for (int a = 0; a < 3; ++a) {
          ASSERT_EQ(wide.start[i].step[a], s.step[a]);
          ASSERT_EQ(wide.start[i].t_max[a], s.t_max[a]) << "batch " << batch << " axis " << a;
          ASSERT_EQ(wide.start[i].t_delta[a], s.t_delta[a]);
          if (end != TraversalEnd::kIrregular) {
            ASSERT_EQ(wide.crossings[i][a], crossings[a]);
          }
        }
        if (end != TraversalEnd::kClean) continue;
        ++clean;
        ASSERT_EQ(wide.times[i].scale, times.scale);
        for (int a = 0; a < 3; ++a) ASSERT_EQ(wide.times[i].last[a], times.last[a]);
      }
    }
  }
  EXPECT_GT(rays, 80000U);
  EXPECT_GT(clean, 20000U);
  if (!hasWideLanes() && !hasFourLanes())
    std::cout << "no AVX2 here: both were the scalar starts\n";
}

// The queued walks (markRaysQueued, DenseMarks::markQueued: eight lanes side by side with
// AVX-512, four with AVX2, or one walk at a time) mark what markRay marks into a hash, walks
// leaving the box included (those are not queued), in batches of any size.
TEST(DenseMarks, QueuedWalksMarkAsTheHashInLanesAndOneByOne) {
  const VoxelGrid grid(0.2);
  for (const auto kernel : {DenseMarks::WalkKernel::kBest,
                            DenseMarks::WalkKernel::kFour, DenseMarks::WalkKernel::kFixedEight,
                            DenseMarks::WalkKernel::kFixedSixteen,
                            DenseMarks::WalkKernel::kScalar}) {
    test::RandomRays random(0.2, 12.0, 17);
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> batch_size(1, 300);
    DenseMarks dense;
    std::size_t queued_all = 0;
    for (int round = 0; round < 3; ++round) {
      const VoxelKey lo = *grid.pointToKey(Point3f(-9.0F, -8.0F, -7.0F));
      const VoxelKey hi = *grid.pointToKey(Point3f(8.0F, 9.0F, 6.0F));
      ASSERT_TRUE(dense.reset(lo, hi, 1U << 20));
      ScanUpdate plain, sut;
      DenseSink sink{dense, sut};
      MarkCounts plain_counts, sut_counts;
      std::size_t queued = 0;
      int left_in_batch = batch_size(rng);
      for (int i = 0; i < 4000; ++i) {
        const test::Ray ray = random.next(test::kAllRayKinds[i % 8]);
        const RayEnd end = rayEndFor(grid, ray.origin, ray.end, 11.0);
        markRay(grid, ray.origin, end, plain, plain_counts);
        const auto origin_key = grid.pointToKey(ray.origin);
        if (!origin_key) continue;
        const std::uint32_t first = 0;  // one ray (a batch shares its origin)
        queued +=
            markRaysQueued(grid, ray.origin, &end, {&first, 1}, sink, sut_counts, *origin_key);
        if (--left_in_batch == 0) {
          dense.markQueued(kernel);
          left_in_batch = batch_size(rng);
        }
      }
      dense.markQueued(kernel);
      dense.flushInto(sut);
      ASSERT_EQ(sut_counts.visits, plain_counts.visits);
      EXPECT_GT(plain.freeCount(), 50000U);
      EXPECT_GT(queued, 400U);  // and the others (short, unsure, leaving the box) marked at once
      queued_all += queued;
      EXPECT_EQ(sut.freeCount(), plain.freeCount()) << "round " << round;
      EXPECT_EQ(markedCells(plain), markedCells(sut)) << "round " << round;
    }
    if ((kernel == DenseMarks::WalkKernel::kFixedEight ||
         kernel == DenseMarks::WalkKernel::kFixedSixteen) &&
        DenseMarks::hasFourWalks()) {
      // Decisions too close to call in fixed point are few, even among these rays (on grid
      // planes, edges and corners, along the axes: many exact ties).
      std::cout << "fixed point: " << dense.fixedHandedOver() << " of " << queued_all
                << " walks handed over\n";
      EXPECT_LT(dense.fixedHandedOver(), queued_all / 4);
    }
  }
  if (!DenseMarks::hasWideWalks()) std::cout << "no AVX-512 here: kBest was not eight lanes\n";
  if (!DenseMarks::hasFourWalks()) std::cout << "no AVX2 here: kFour walked one by one\n";
}

// Queued walks through exact ties of two axes' crossing times on the way (dyadic origins and
// directions of exact ratios): the lanes break them as countedSteps does (to the higher axis).
TEST(DenseMarks, QueuedWalksBreakExactTiesAsTheCountedLoop) {
  const VoxelGrid grid(0.25);
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> lattice(-40, 40), scale(3, 40), pick(0, 5);
  std::size_t tied = 0;
  for (const auto kernel : {DenseMarks::WalkKernel::kBest,
                            DenseMarks::WalkKernel::kFour, DenseMarks::WalkKernel::kFixedEight,
                            DenseMarks::WalkKernel::kFixedSixteen,
                            DenseMarks::WalkKernel::kScalar}) {
    DenseMarks dense;
    const VoxelKey lo = *grid.pointToKey(Point3f(-30.0F, -30.0F, -30.0F));
    const VoxelKey hi = *grid.pointToKey(Point3f(30.0F, 30.0F, 30.0F));
    ASSERT_TRUE(dense.reset(lo, hi, 1U << 21));
    ScanUpdate plain, sut;
    DenseSink sink{dense, sut};
    MarkCounts plain_counts, sut_counts;
    tied = 0;
    for (int i = 0; i < 20000; ++i) {
      const Point3f origin(static_cast<float>(lattice(rng)) / 64.0F,
                           static_cast<float>(lattice(rng)) / 64.0F,
                           static_cast<float>(lattice(rng)) / 64.0F);
      const float m = static_cast<float>(scale(rng)) / 8.0F;
      static constexpr float kRatios[6][3] = {{2, 1, 0.5F},  {1, 2, 0.25F}, {1, 0.5F, 2},
                                              {-2, 1, 0.5F}, {4, -1, 2},    {1, -4, -0.5F}};
      const auto& r = kRatios[pick(rng)];
      const Point3f end = origin + m * Point3f(r[0], r[1], r[2]);
      const RayEnd ray = rayEndFor(grid, origin, end, -1.0);
      markRay(grid, origin, ray, plain, plain_counts);
      const VoxelKey origin_key = *grid.pointToKey(origin);
      const std::uint32_t first = 0;
      if (markRaysQueued(grid, origin, &ray, {&first, 1}, sink, sut_counts, origin_key) == 0) {
        continue;
      }
      // An exact tie between the two smallest times at some step of the counted loop?
      TraversalStart s;
      startTraversal(grid, origin, origin_key, ray.end, ray.key, s);
      double t[3] = {s.t_max[0], s.t_max[1], s.t_max[2]};
      bool tie = false;
      for (int n = 1; n < countedTotal(s); ++n) {
        const int a = (t[0] < t[1] && t[0] < t[2]) ? 0 : (!(t[0] < t[1]) && t[1] < t[2]) ? 1 : 2;
        for (int b = 0; b < 3; ++b) tie = tie || (b != a && t[b] == t[a]);
        t[a] += s.t_delta[a];
      }
      tied += tie ? 1 : 0;
      if (i % 97 == 0) dense.markQueued(kernel);
    }
    dense.markQueued(kernel);
    dense.flushInto(sut);
    ASSERT_EQ(sut_counts.visits, plain_counts.visits);
    std::vector<std::uint64_t> a, b;
    plain.forEachCell([&](const VoxelKey& k, const CellHits&) { a.push_back(k.packed()); });
    sut.forEachCell([&](const VoxelKey& k, const CellHits&) { b.push_back(k.packed()); });
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    EXPECT_EQ(a, b);
    if ((kernel == DenseMarks::WalkKernel::kFixedEight ||
         kernel == DenseMarks::WalkKernel::kFixedSixteen) &&
        DenseMarks::hasFourWalks()) {
      // An exact tie of the doubles is within the fixed point's slack: each such walk is
      // handed over (and walked exactly by the doubles).
      EXPECT_GE(dense.fixedHandedOver(), tied);
    }
  }
  EXPECT_GT(tied, 100U) << "queued walks with an exact tie on the way";
}

// The forward walks queued straight into fixed point by their rays' indices (markRaysQueued's
// `fixed`, DenseMarks::queueFixedWalks, walkRaysQueued: eight lanes of 32-bit times, the walks
// with a decision too close to call walked again by markRay) mark what markRay marks into a
// hash and count the same visits: random rays, rays through exact ties (dyadic origins and
// directions of exact ratios: handed over), rays leaving the box, batches of any size (each
// flushed and compared: a batch of a few long rays has its origin's voxel marked by the queue
// alone).
// Both fixed-point kernels: eight AVX2 lanes and (where AVX-512 is) sixteen.
class FixedQueueByRayIndex : public ::testing::TestWithParam<DenseMarks::WalkKernel> {};
TEST_P(FixedQueueByRayIndex, MarksAsTheHash) {
  const DenseMarks::WalkKernel kernel = GetParam();
  const VoxelGrid grid(0.25);
  std::mt19937 rng(29);
  std::uniform_int_distribution<int> lattice(-40, 40), scale(3, 60), pick(0, 6), batch(1, 300),
      few(1, 4), many(800, 1500);
  std::uniform_real_distribution<float> coord(-14.0F, 14.0F);
  ASSERT_EQ(DenseMarks::queuesFixed(kernel), DenseMarks::hasFourWalks());
  DenseMarks dense;
  const VoxelKey lo = *grid.pointToKey(Point3f(-10.0F, -10.0F, -10.0F));
  const VoxelKey hi = *grid.pointToKey(Point3f(10.0F, 10.0F, 10.0F));
  ASSERT_TRUE(dense.reset(lo, hi, 1U << 21));
  MarkCounts plain_counts, sut_counts;
  std::vector<RayEnd> rays;
  std::vector<std::uint32_t> ids, handed;
  std::size_t queued = 0, free_cells = 0;
  for (int b = 0; b < 150; ++b) {
    ScanUpdate plain, sut;
    DenseSink sink{dense, sut};
    const Point3f origin(static_cast<float>(lattice(rng)) / 64.0F,
                         static_cast<float>(lattice(rng)) / 64.0F,
                         static_cast<float>(lattice(rng)) / 64.0F);
    const VoxelKey origin_key = *grid.pointToKey(origin);
    rays.clear();
    ids.clear();
    // (Batches of many rays: the queue grows while it holds walks.)
    for (int i = b % 3 == 0 ? few(rng) : b % 10 == 1 ? many(rng) : batch(rng); i > 0; --i) {
      static constexpr float kRatios[6][3] = {{2, 1, 0.5F},  {1, 2, 0.25F}, {1, 0.5F, 2},
                                              {-2, 1, 0.5F}, {4, -1, 2},    {1, -4, -0.5F}};
      const int k = pick(rng);
      const float m = static_cast<float>(scale(rng)) / 8.0F;
      const Point3f end = k == 6
                              ? Point3f(coord(rng), coord(rng), coord(rng))
                              : origin + m * Point3f(kRatios[k][0], kRatios[k][1], kRatios[k][2]);
      ids.push_back(static_cast<std::uint32_t>(rays.size()));
      rays.push_back(rayEndFor(grid, origin, end, -1.0));
      markRay(grid, origin, rays.back(), plain, plain_counts);
    }
    queued += markRaysQueued(grid, origin, rays.data(), ids, sink, sut_counts, origin_key,
                             DenseMarks::queuesFixed(kernel), kernel);
    walkRaysQueued(grid, origin, rays.data(), sink, origin_key, kernel, handed);
    dense.flushInto(sut);
    ASSERT_EQ(sut_counts.visits, plain_counts.visits) << "batch " << b;
    ASSERT_EQ(markedCells(plain), markedCells(sut)) << "batch " << b << " of " << rays.size();
    free_cells += plain.freeCount();
  }
  EXPECT_GT(free_cells, 50000U);
  EXPECT_GT(queued, 5000U);
  if (DenseMarks::hasFourWalks()) {
    // The exact ties (a few per cent of these rays) are handed over and walked again.
    std::cout << "fixed point by ray index: " << dense.fixedHandedOver() << " of " << queued
              << " walks handed over\n";
    EXPECT_GT(dense.fixedHandedOver(), 50U);
    EXPECT_LT(dense.fixedHandedOver(), queued / 4);
  } else {
    std::cout << "no AVX2 here: the walks were queued for markQueued\n";
  }
}
INSTANTIATE_TEST_SUITE_P(DenseMarks, FixedQueueByRayIndex,
                         ::testing::Values(DenseMarks::WalkKernel::kFixedEight,
                                           DenseMarks::WalkKernel::kFixedSixteen));

/// Alg. 3 as written: breadth-first from the sensor's voxel over fully-free voxels whose test
/// cells are all in the region.
/// With `marked`, grown by the voxels the scan marked free too (CullingRegion::grow).
std::set<std::uint64_t> bfsRegion(const OccupancyMap& map, const VoxelKey& o, const KeyBox& box,
                                  const std::set<std::uint64_t>& hit,
                                  const std::set<std::uint64_t>& marked = {}) {
  const auto free = [&](const VoxelKey& k) {
    for (int a = 0; a < 3; ++a) {
      if (k[a] < box.min[a] || k[a] > box.max[a]) return false;
    }
    if (marked.contains(k.packed())) return true;
    const auto v = map.logOdds(k);
    return v && map.sensorModel().isFullyFree(*v) && !hit.contains(k.packed());
  };
  std::set<std::uint64_t> region;
  std::deque<VoxelKey> queue;
  if (!free(o)) return region;
  region.insert(o.packed());
  queue.push_back(o);
  while (!queue.empty()) {
    const VoxelKey c = queue.front();
    queue.pop_front();
    for (int a = 0; a < 3; ++a) {
      for (const int d : {-1, 1}) {
        VoxelKey n = c;
        n[a] = static_cast<std::uint16_t>(n[a] + d);
        if (region.contains(n.packed()) || !free(n)) continue;
        bool tests_in = true;  // every neighbour one step closer to o must be in the region
        for (int b = 0; b < 3 && tests_in; ++b) {
          if (n[b] == o[b]) continue;
          VoxelKey t = n;
          t[b] = static_cast<std::uint16_t>(n[b] > o[b] ? n[b] - 1 : n[b] + 1);
          tests_in = region.contains(t.packed());
        }
        if (!tests_in) continue;
        region.insert(n.packed());
        queue.push_back(n);
      }
    }
  }
  return region;
}

TEST(CullingRegion, EqualsBreadthFirstAlgorithm3OnRandomMaps) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 12; ++trial) {
    GridMap map(0.1, SensorModel{});
    const VoxelKey o{32768, 32770, 32765};
    std::uniform_int_distribution<int> off(-14, 14);
    std::bernoulli_distribution blocked(trial % 2 == 0 ? 0.03 : 0.12);
    for (int dz = -14; dz <= 14; ++dz) {
      for (int dy = -14; dy <= 14; ++dy) {
        for (int dx = -14; dx <= 14; ++dx) {
          const VoxelKey k{static_cast<std::uint16_t>(o.x + dx),
                           static_cast<std::uint16_t>(o.y + dy),
                           static_cast<std::uint16_t>(o.z + dz)};
          map.setLogOdds(k, blocked(rng) ? 0.5F : map.sensorModel().clampMin());
        }
      }
    }
    std::vector<VoxelKey> hit;
    std::set<std::uint64_t> hit_set;
    for (int i = 0; i < 20; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(o.x + off(rng)),
                       static_cast<std::uint16_t>(o.y + off(rng)),
                       static_cast<std::uint16_t>(o.z + off(rng))};
      hit.push_back(k);
      hit_set.insert(k.packed());
    }
    // A box reaching past the known voxels on some sides and cutting them on others.
    const KeyBox box{{static_cast<std::uint16_t>(o.x - 9), static_cast<std::uint16_t>(o.y - 16),
                      static_cast<std::uint16_t>(o.z - 14)},
                     {static_cast<std::uint16_t>(o.x + 70), static_cast<std::uint16_t>(o.y + 12),
                      static_cast<std::uint16_t>(o.z + 16)}};
    CullingRegion sut;
    sut.build(map, o, box, hit);
    // The same region indexed in a larger frame, shared with a DenseMarks of that box:
    // markFreeUnlessIn refuses exactly the region's voxels.
    const KeyBox frame{{static_cast<std::uint16_t>(o.x - 30), static_cast<std::uint16_t>(o.y - 21),
                        static_cast<std::uint16_t>(o.z - 17)},
                       {static_cast<std::uint16_t>(o.x + 75), static_cast<std::uint16_t>(o.y + 19),
                        static_cast<std::uint16_t>(o.z + 18)}};
    CullingRegion framed;
    framed.build(map, o, box, hit, &frame);
    DenseMarks marks;
    ASSERT_TRUE(marks.reset(frame.min, frame.max, 1U << 20));
    const bool shared = framed.sharesFrame(marks);  // an empty region has no bricks
    ASSERT_EQ(shared, sut.size() != 0);
    EXPECT_EQ(sut.sharesFrame(marks), false);
    ScanUpdate outside;
    outside.reset(UpdateRule::kSet);
    const auto expected = bfsRegion(map, o, box, hit_set);
    std::size_t found = 0;
    for (int dz = -20; dz <= 20; ++dz) {
      for (int dy = -20; dy <= 20; ++dy) {
        for (int dx = -20; dx <= 80; ++dx) {
          const VoxelKey k{static_cast<std::uint16_t>(o.x + dx),
                           static_cast<std::uint16_t>(o.y + dy),
                           static_cast<std::uint16_t>(o.z + dz)};
          const bool in = sut.contains(k);
          ASSERT_EQ(in, expected.contains(k.packed()))
              << "trial " << trial << " at " << dx << "," << dy << "," << dz;
          ASSERT_EQ(framed.contains(k), in);
          if (shared) {
            ASSERT_EQ(marks.markFreeUnlessIn(framed, k, outside), !in);
          }
          found += in ? 1 : 0;
        }
      }
    }
    EXPECT_EQ(found, expected.size());
    EXPECT_EQ(sut.size(), expected.size());
    if (trial % 2 == 0) {
      EXPECT_GT(expected.size(), 300U);
    }
  }
}

TEST(CullingRegion, GrowsByTheScansMarksAsBreadthFirstOverFullyFreeOrMarkedVoxels) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 8; ++trial) {
    GridMap map(0.1, SensorModel{});
    const VoxelKey o{32771, 32766, 32768};
    std::bernoulli_distribution fully_free(trial % 2 == 0 ? 0.6 : 0.3);
    std::bernoulli_distribution mark(0.5);
    std::uniform_int_distribution<int> off(-10, 10);
    std::set<std::uint64_t> marked_once, marked_twice, hit_set;
    for (int dz = -12; dz <= 12; ++dz) {
      for (int dy = -12; dy <= 12; ++dy) {
        for (int dx = -12; dx <= 12; ++dx) {
          const VoxelKey k{static_cast<std::uint16_t>(o.x + dx),
                           static_cast<std::uint16_t>(o.y + dy),
                           static_cast<std::uint16_t>(o.z + dz)};
          // Trials 2 and 3: the sensor's voxel is not fully free, only marked.
          const bool free = fully_free(rng) && !(trial / 2 == 1 && k == o);
          map.setLogOdds(k, free ? map.sensorModel().clampMin() : -0.4F);
          if (mark(rng)) marked_once.insert(k.packed());
          if (mark(rng)) marked_twice.insert(k.packed());
        }
      }
    }
    marked_once.insert(o.packed());
    std::vector<VoxelKey> hit;
    for (int i = 0; i < 25; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(o.x + off(rng)),
                       static_cast<std::uint16_t>(o.y + off(rng)),
                       static_cast<std::uint16_t>(o.z + off(rng))};
      hit.push_back(k);
      hit_set.insert(k.packed());
    }
    const KeyBox box{{static_cast<std::uint16_t>(o.x - 10), static_cast<std::uint16_t>(o.y - 13),
                      static_cast<std::uint16_t>(o.z - 9)},
                     {static_cast<std::uint16_t>(o.x + 14), static_cast<std::uint16_t>(o.y + 11),
                      static_cast<std::uint16_t>(o.z + 12)}};
    const KeyBox frame{{static_cast<std::uint16_t>(o.x - 20), static_cast<std::uint16_t>(o.y - 20),
                        static_cast<std::uint16_t>(o.z - 20)},
                       {static_cast<std::uint16_t>(o.x + 20), static_cast<std::uint16_t>(o.y + 20),
                        static_cast<std::uint16_t>(o.z + 20)}};
    CullingRegion sut;
    sut.build(map, o, box, hit, &frame, /*growable=*/true);
    // Before growing: the map's region (empty when the sensor's voxel is not fully free).
    const auto from_map = bfsRegion(map, o, box, hit_set);
    ASSERT_EQ(sut.size(), from_map.size()) << "trial " << trial;
    // The marks as DenseMarks hands them over, in two calls (the second ORed in).
    std::set<std::uint64_t> marked;
    for (const auto* set : {&marked_once, &marked_twice}) {
      DenseMarks marks;
      ASSERT_TRUE(marks.reset(frame.min, frame.max, 1U << 20));
      ScanUpdate outside;
      outside.reset(UpdateRule::kSet);
      for (const std::uint64_t packed : *set) marks.markFree(VoxelKey::fromPacked(packed), outside);
      std::vector<FullyFreeBlock> covered;
      marks.forEachMarkedFree([&](std::uint64_t key, const block::BlockMask& mask) {
        covered.push_back({key, mask});
      });
      sut.grow(covered);
      marked.insert(set->begin(), set->end());
      const auto expected = bfsRegion(map, o, box, hit_set, marked);
      std::size_t found = 0;
      for (int dz = -14; dz <= 14; ++dz) {
        for (int dy = -14; dy <= 14; ++dy) {
          for (int dx = -14; dx <= 16; ++dx) {
            const VoxelKey k{static_cast<std::uint16_t>(o.x + dx),
                             static_cast<std::uint16_t>(o.y + dy),
                             static_cast<std::uint16_t>(o.z + dz)};
            ASSERT_EQ(sut.contains(k), expected.contains(k.packed()))
                << "trial " << trial << " at " << dx << "," << dy << "," << dz;
            found += sut.contains(k) ? 1 : 0;
          }
        }
      }
      EXPECT_EQ(found, expected.size());
      EXPECT_EQ(sut.size(), expected.size());
      EXPECT_GT(expected.size(), from_map.size()) << "trial " << trial;
    }
  }
}

// The queued backward walks (markRaysCulledQueued, DenseMarks::markQueuedBack in lanes or one by
// one, handed-over walks walked again by markCrossedCulled) mark and count what markRayCulled does
// with a culling region sharing the dense box's frame, on rays from the sensor's voxel and from
// around it (adversarial kinds: near-ties hand over).
TEST(DenseMarks, QueuedBackwardWalksMarkAndCountAsMarkRayCulled) {
  std::mt19937 rng(9);
  std::size_t queued = 0, handed = 0, fixed_handed = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const double resolution = 0.25;  // dyadic: exact ties on the way (below) hand over
    GridMap map(resolution, SensorModel{});
    const VoxelGrid& grid = map.grid();
    const Point3f origin(0.03F, -0.04F, 0.02F);
    const VoxelKey o = *grid.pointToKey(origin);
    std::bernoulli_distribution blocked(trial % 2 == 0 ? 0.0005 : 0.003);
    for (int dz = -25; dz <= 25; ++dz) {
      for (int dy = -25; dy <= 25; ++dy) {
        for (int dx = -25; dx <= 25; ++dx) {
          const VoxelKey k{static_cast<std::uint16_t>(o.x + dx),
                           static_cast<std::uint16_t>(o.y + dy),
                           static_cast<std::uint16_t>(o.z + dz)};
          const bool block = blocked(rng) && k != o;
          map.setLogOdds(k, block ? 0.5F : map.sensorModel().clampMin());
        }
      }
    }
    test::RandomRays random(resolution, 2.5, 40 + trial);
    std::vector<RayEnd> rays;
    std::vector<Point3f> origins;
    std::uniform_int_distribution<int> lattice(-40, 40), scale(3, 40), pick(0, 2);
    for (int i = 0; i < 3000; ++i) {
      // A quarter of the rays from the sensor's point, a quarter with exact ratios of their
      // direction's coordinates from dyadic points (exact ties between axes on the way), the
      // others from anywhere.
      test::Ray ray = random.next(test::kAllRayKinds[i % 8]);
      if (i % 4 == 0) ray.origin = origin;
      if (i % 4 == 1) {
        static constexpr float kRatios[3][3] = {{2, 1, 0.5F}, {-1, 2, 0.25F}, {1, -0.5F, -2}};
        const auto& r = kRatios[pick(rng)];
        ray.origin = Point3f(static_cast<float>(lattice(rng)) / 64.0F,
                             static_cast<float>(lattice(rng)) / 64.0F,
                             static_cast<float>(lattice(rng)) / 64.0F);
        ray.end = ray.origin + static_cast<float>(scale(rng)) / 32.0F * Point3f(r[0], r[1], r[2]);
      }
      rays.push_back(rayEndFor(grid, ray.origin, ray.end, 3.0));
      origins.push_back(ray.origin);
    }
    const VoxelKey lo = *grid.pointToKey(Point3f(-4.0F, -4.0F, -4.0F));
    const VoxelKey hi = *grid.pointToKey(Point3f(4.0F, 4.0F, 4.0F));
    const KeyBox frame{lo, hi};
    CullingRegion region;
    // (The rays' ends not excluded: the region need not be exact for the walks, only shared.)
    region.build(map, o, KeyBox{lo, hi}, {}, &frame);
    ASSERT_GT(region.size(), 1000U);
    for (const auto kernel : {DenseMarks::WalkKernel::kBest,
                              DenseMarks::WalkKernel::kFour, DenseMarks::WalkKernel::kFixedEight,
                              DenseMarks::WalkKernel::kFixedSixteen,
                              DenseMarks::WalkKernel::kScalar}) {
      DenseMarks plain_marks, sut_marks;
      ASSERT_TRUE(plain_marks.reset(lo, hi, 1U << 20));
      ASSERT_TRUE(sut_marks.reset(lo, hi, 1U << 20));
      ASSERT_TRUE(region.sharesFrame(sut_marks));
      ScanUpdate plain, sut;
      SharedFrameSink plain_sink{{plain_marks, plain}}, sut_sink{{sut_marks, sut}};
      MarkCounts plain_counts, sut_counts;
      BackwardScratch scratch;
      std::vector<std::uint32_t> handed_over;
      const auto walk_queue = [&] {
        handed_over.clear();
        const auto walked = sut_marks.markQueuedBack(region.frameMasks(), handed_over, kernel);
        sut_counts.visits += walked.visits;
        sut_counts.culled += walked.culled;
        for (const std::uint32_t i : handed_over) {
          const VoxelKey ok = *grid.pointToKey(origins[i]);
          markCrossedCulled(grid, origins[i], rays[i], region, scratch, sut_sink, sut_counts, &ok);
        }
        handed += handed_over.size();
      };
      for (std::uint32_t i = 0; i < rays.size(); ++i) {
        const auto ok = grid.pointToKey(origins[i]);
        if (!ok) continue;
        markRayCulled(grid, origins[i], rays[i], region, scratch, plain_sink, plain_counts, &*ok);
        queued += markRaysCulledQueued(grid, origins[i], rays.data(), {&i, 1}, region, scratch,
                                       sut_sink, sut_counts, *ok);
        if (i % 211 == 0) walk_queue();
      }
      walk_queue();
      plain_marks.flushInto(plain);
      sut_marks.flushInto(sut);
      EXPECT_EQ(sut_counts.visits, plain_counts.visits) << "trial " << trial;
      EXPECT_EQ(sut_counts.culled, plain_counts.culled) << "trial " << trial;
      EXPECT_GT(plain_counts.culled, 1000U);
      EXPECT_EQ(markedCells(plain), markedCells(sut)) << "trial " << trial;
      if (kernel == DenseMarks::WalkKernel::kFixedEight && DenseMarks::hasFourWalks()) {
        // The dyadic rays' exact ties are too close to call in fixed point: handed over (to the
        // doubles' lanes), but not most walks.
        fixed_handed += sut_marks.fixedHandedOver();
      }
    }
  }
  EXPECT_GT(queued, 10000U);
  EXPECT_GT(handed, 10U) << "walks handed over to the exact walk";
  if (DenseMarks::hasFourWalks()) {
    EXPECT_GT(fixed_handed, 10U);
    EXPECT_LT(fixed_handed, queued / 4 / 4);  // queued counts the four kernels' walks
  }
}

TEST(CullingRegion, IsEmptyWhenTheSensorsVoxelIsNotFullyFreeAndBoxesFitTheBudget) {
  GridMap map(0.1, SensorModel{});
  const VoxelKey o{32768, 32768, 32768};
  map.setLogOdds(o, -1.0F);
  CullingRegion sut;
  sut.build(map, o, {o, o}, {});
  EXPECT_EQ(sut.size(), 0U);
  const KeyBox big{{30000, 30000, 32000}, {35000, 35000, 33000}};
  const KeyBox fitted = cullingBox(o, big, 1'000'000);
  std::size_t voxels = 1;
  for (int a = 0; a < 3; ++a) {
    EXPECT_LE(fitted.min[a], o[a]);
    EXPECT_GE(fitted.max[a], o[a]);
    voxels *= static_cast<std::size_t>(fitted.max[a] - fitted.min[a]) + 1;
  }
  EXPECT_LE(voxels, 1'000'000U);
  EXPECT_GT(voxels, 500'000U);
}

// A scan with a return ~1e-30 m from the sensor, across a voxel border (a sensor at a
// grid plane), integrates with every method instead of hanging the pipeline (OctoMap itself
// loops forever on it, so the methods are compared with each other).
TEST(AllMethods, AReturnTooCloseForAFloatLengthDoesNotHang) {
  const double resolution = 0.1;
  const Point3f origin(0.0F, 0.0F, 0.0F);  // on the grid planes x, y, z = 0
  PointCloud cloud = test::adversarialScan(resolution, origin, 500, 3.0, 77);
  cloud.emplace_back(-1e-30F, -1e-30F, 0.0F);
  cloud.emplace_back(0.0F, -3e-24F, 0.0F);
  GridMap reference(resolution, SensorModel{});
  (void)Integrator({.method = IntegrationMethod::kRaycast}).integrate(reference, cloud, origin);
  ASSERT_GT(reference.knownCells(), 100U);
  for (const auto method : {IntegrationMethod::kSuperRay, IntegrationMethod::kCulling,
                            IntegrationMethod::kSuperRayCulling}) {
    GridMap map(resolution, SensorModel{});
    for (int scan = 0; scan < 2; ++scan) {
      (void)Integrator({.method = method}).integrate(map, cloud, origin);
      if (scan == 0) {
        const MapDiff diff = diffMaps(map, reference);
        EXPECT_EQ(diff.differing(), 0U) << methodName(method);
      }
    }
  }
}

}  // namespace
}  // namespace densemap

#include "../../integration/exactness_harness.hpp"

namespace densemap {
namespace {

TEST(AllMethods, AgreeOnAdversarialScansWithAMovingOrigin) {
  for (const double resolution : {0.1, 0.2, 0.15}) {
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    test::RandomRays origins(resolution, 1.0, 29);
    std::vector<test::WorldScan> scans;
    // Dwell on one origin (on grid planes) so voxels saturate and culling starts, then move
    // (every other origin on grid planes), then come back.
    const Point3f home = origins.point(1.0);
    for (int i = 0; i < 12; ++i) {
      const Point3f origin = i < 7 || i == 11 ? home : origins.point(i % 2 == 0 ? 1.0 : 0.0);
      PointCloud cloud = test::adversarialScan(resolution, origin, 6000, 5.0, 300 + i);
      // No return inside the sensor's own voxel: it must be free for the culling region to grow
      // (Alg. 3 starts there).
      const VoxelGrid grid(resolution);
      std::erase_if(
          cloud, [&](const Point3f& p) { return grid.pointToKey(p) == grid.pointToKey(origin); });
      scans.push_back({std::move(cloud), origin});
    }
    test::expectMethodsAgree(scans, resolution, 4.0);
  }
}

}  // namespace
}  // namespace densemap
