// Kernel inference (dissertation Ch. 3): kernel values, the scale fit of Eq. 3.7, covariance
// shapes, the map's behaviour and determinism for all four methods, and akimap_rays' parts.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <vector>

#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/kernel_function.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/traversal/ray_traversal.hpp"
#include "free_bundles.hpp"
#include "kernel_fit.hpp"
#include "segment_voxels.hpp"

namespace densemap::kernel {
namespace {

TEST(SparseKernel, MatchesHandComputedValues) {
  EXPECT_DOUBLE_EQ(sparseKernel(0.0), 1.0);
  EXPECT_NEAR(sparseKernel(0.25), 0.5 + 1.0 / (2.0 * std::numbers::pi), 1e-12);
  EXPECT_NEAR(sparseKernel(0.5), 1.0 / 6.0, 1e-12);
  EXPECT_NEAR(sparseKernel(0.75), (2.0 / 3.0) * 0.25 - 1.0 / (2.0 * std::numbers::pi), 1e-12);
  EXPECT_EQ(sparseKernel(1.0), 0.0);
  EXPECT_EQ(sparseKernel(3.0), 0.0);
  EXPECT_EQ(sparseKernel(std::nan("")), 0.0);
  // Monotone decreasing on [0, 1).
  for (double r = 0.0; r < 0.99; r += 0.01) EXPECT_GT(sparseKernel(r), sparseKernel(r + 0.01));
}

std::vector<Neighbour> ringOfPositives(double radius) {
  std::vector<Neighbour> n;
  for (int i = 0; i < 8; ++i) {
    const double a = i * std::numbers::pi / 4.0;
    n.push_back({Eigen::Vector3d(radius * std::cos(a), radius * std::sin(a), 0.0), true});
  }
  return n;
}

TEST(FitScale, PositiveNeighboursOnlyKeepTheCovariance) {
  const Eigen::Matrix3d sigma = 0.04 * Eigen::Matrix3d::Identity();  // 0.2 m std
  const auto neighbours = ringOfPositives(0.1);
  EXPECT_NEAR(scaleObjective(1.0, sigma, Eigen::Vector3d::Zero(), neighbours), 0.0, 1e-15);
  EXPECT_NEAR(fitScale(sigma, Eigen::Vector3d::Zero(), neighbours, 1.0 / 16, 16.0), 1.0, 0.05);
}

TEST(FitScale, NegativeNeighbourInsideTheSupportShrinksTheKernel) {
  const Eigen::Matrix3d sigma = 0.04 * Eigen::Matrix3d::Identity();
  auto neighbours = ringOfPositives(0.05);
  neighbours.push_back({Eigen::Vector3d(0.12, 0.0, 0.0), false});  // r = 0.6 at s = 1
  const double s = fitScale(sigma, Eigen::Vector3d::Zero(), neighbours, 1.0 / 16, 16.0);
  EXPECT_LT(s, 1.0);
  // It is the minimiser of Eq. 3.7 among nearby scales.
  const double f = scaleObjective(s, sigma, Eigen::Vector3d::Zero(), neighbours);
  for (const double other : {0.5 * s, 0.8 * s, 1.25 * s, 1.0}) {
    EXPECT_LE(f, scaleObjective(other, sigma, Eigen::Vector3d::Zero(), neighbours) + 1e-12);
  }
  // And the shrunk kernel no longer (or barely) reaches the negative neighbour.
  EXPECT_LT(sparseKernel(0.12 / std::sqrt(0.04 * s)), sparseKernel(0.6));
}

TEST(FitScale, MoreNegativeNeighboursShrinkMore) {
  const Eigen::Matrix3d sigma = 0.04 * Eigen::Matrix3d::Identity();
  auto one = ringOfPositives(0.05);
  one.push_back({Eigen::Vector3d(0.15, 0.0, 0.0), false});
  auto closer = one;
  closer.push_back({Eigen::Vector3d(0.0, 0.08, 0.0), false});
  const double s_one = fitScale(sigma, Eigen::Vector3d::Zero(), one, 1.0 / 16, 16.0);
  const double s_closer = fitScale(sigma, Eigen::Vector3d::Zero(), closer, 1.0 / 16, 16.0);
  EXPECT_LT(s_closer, s_one);
}

// Fig. 3.3-(c): "a positive neighbour ... prevents the kernel estimation from having too small
// range". Under Eq. 3.6-3.7 a positive neighbour's target is its kernel value at s = 1, so a
// positive neighbour inside that support resists shrinking (k falls below its target), while one
// outside it (target 0) leaves every s <= 1 unchanged; it cannot grow the kernel beyond s = 1.
TEST(FitScale, PositiveNeighboursInsideTheSupportHoldBackTheShrinking) {
  const Eigen::Matrix3d sigma = 0.04 * Eigen::Matrix3d::Identity();
  std::vector<Neighbour> negative_only{{Eigen::Vector3d(0.08, 0.0, 0.0), false}};  // r = 0.4
  auto with_positives = negative_only;
  for (const Neighbour& n : ringOfPositives(0.14)) with_positives.push_back(n);  // r = 0.7
  const double s_neg = fitScale(sigma, Eigen::Vector3d::Zero(), negative_only, 1.0 / 16, 16.0);
  const double s_pos = fitScale(sigma, Eigen::Vector3d::Zero(), with_positives, 1.0 / 16, 16.0);
  RecordProperty("s_negative_only", std::to_string(s_neg));
  RecordProperty("s_with_positives", std::to_string(s_pos));
  EXPECT_LT(s_neg, 0.5);
  EXPECT_GT(s_pos, s_neg * 1.2);
  EXPECT_LT(s_pos, 1.0);
}

TEST(FitScale, PositiveNeighboursOutsideTheSupportDoNotChangeTheFit) {
  const Eigen::Matrix3d sigma = 0.04 * Eigen::Matrix3d::Identity();
  auto base = ringOfPositives(0.05);
  base.push_back({Eigen::Vector3d(0.12, 0.0, 0.0), false});
  auto far = base;
  for (const Neighbour& n : ringOfPositives(0.25)) far.push_back(n);  // r = 1.25 at s = 1
  for (const double s : {0.3, 0.6, 1.0}) {
    EXPECT_DOUBLE_EQ(scaleObjective(s, sigma, Eigen::Vector3d::Zero(), base),
                     scaleObjective(s, sigma, Eigen::Vector3d::Zero(), far));
  }
  EXPECT_NEAR(fitScale(sigma, Eigen::Vector3d::Zero(), far, 1.0 / 16, 16.0),
              fitScale(sigma, Eigen::Vector3d::Zero(), base, 1.0 / 16, 16.0), 1e-9);
}

TEST(NeighbourCovariance, SamplesOnAPlaneGiveAFlatKernelAlignedWithIt) {
  std::vector<Neighbour> plane;
  for (int i = -3; i <= 3; ++i) {
    for (int j = -3; j <= 3; ++j) {
      if (i == 0 && j == 0) continue;
      // The plane x + y + z = 0 (normal (1,1,1)/sqrt(3)).
      const Eigen::Vector3d u = Eigen::Vector3d(1, -1, 0).normalized();
      const Eigen::Vector3d v = Eigen::Vector3d(1, 1, -2).normalized();
      plane.push_back({0.05 * i * u + 0.05 * j * v, true});
    }
  }
  plane.push_back({Eigen::Vector3d(0.3, 0.3, 0.3), false});  // other labels do not shape it
  const Eigen::Matrix3d sigma = neighbourCovariance(Eigen::Vector3d::Zero(), plane, 1e-6, 1.0);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(sigma);
  EXPECT_LT(eig.eigenvalues()[0] * 100, eig.eigenvalues()[1]);  // flat
  const Eigen::Vector3d normal = eig.eigenvectors().col(0);
  EXPECT_NEAR(std::abs(normal.dot(Eigen::Vector3d(1, 1, 1).normalized())), 1.0, 1e-6);
  // Too few positive neighbours: isotropic fallback.
  const std::vector<Neighbour> few = {{Eigen::Vector3d(0.1, 0, 0), true}};
  EXPECT_TRUE(neighbourCovariance(Eigen::Vector3d::Zero(), few, 1e-6, 0.5)
                  .isApprox(0.5 * Eigen::Matrix3d::Identity()));
}

/// A wall at x = 3 m seen from the origin.
PointCloud wallScan() {
  PointCloud points;
  for (double y = -1.0; y <= 1.0; y += 0.04) {
    for (double z = -0.5; z <= 0.5; z += 0.08) {
      points.emplace_back(3.0F, static_cast<float>(y), static_cast<float>(z));
    }
  }
  return points;
}

/// A wall at x = 3 m and a floor at z = -1.2 m out to 12 m, seen from `origin`: grazing rays.
PointCloud roomScan() {
  PointCloud points = wallScan();
  for (double x = 0.5; x <= 12.0; x += 0.07) {
    for (double y = -2.0; y <= 2.0; y += 0.09) {
      points.emplace_back(static_cast<float>(x), static_cast<float>(y), -1.2F);
    }
  }
  points.emplace_back(25.0F, 0.0F, 0.5F);  // beyond max range: a cut ray
  return points;
}

std::vector<std::pair<std::uint64_t, double>> cellsOf(const KernelMap& map) {
  std::vector<std::pair<std::uint64_t, double>> cells;
  map.forEachKnown([&](const VoxelKey& k, double p) { cells.emplace_back(k.packed(), p); });
  std::sort(cells.begin(), cells.end());
  return cells;
}

class KernelMapMethods : public ::testing::TestWithParam<KernelMethod> {};

TEST_P(KernelMapMethods, WallIsOccupiedFreeSpaceIsFreeFarAwayIsUnknown) {
  KernelOptions options = KernelOptions::defaults(GetParam());
  options.max_range = 10.0;
  KernelMap map(0.1, options);
  const auto stats = map.integrate(wallScan(), Point3f(0, 0, 0));
  // A kernel per sample (free ones too), but akimap_rays': per voxel of hits (adaptive, and a
  // tabled hit kernel per sub-position), so fewer than the points.
  EXPECT_GT(stats.samples,
            GetParam() == KernelMethod::kAkimapRays ? wallScan().size() / 4 : wallScan().size());
  EXPECT_GT(stats.cell_updates, 0U);
  const auto at = [&](float x, float y, float z) {
    return map.probability(*map.grid().pointToKey(Point3f(x, y, z)));
  };
  ASSERT_TRUE(at(3.02F, 0.02F, 0.02F).has_value());
  EXPECT_GT(*at(3.02F, 0.02F, 0.02F), 0.5);
  ASSERT_TRUE(at(1.5F, 0.02F, 0.02F).has_value());
  EXPECT_LT(*at(1.5F, 0.02F, 0.02F), 0.5);
  EXPECT_FALSE(at(-5.0F, 4.0F, 0.0F).has_value());
  EXPECT_GT(map.knownCells(), 100U);
}

TEST_P(KernelMapMethods, ResultDoesNotDependOnTheThreadCount) {
  const auto build = [](KernelMethod method, int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    KernelOptions options = KernelOptions::defaults(method);
    options.seed = 7;
    KernelMap map(0.1, options);
    map.integrate(wallScan(), Point3f(0, 0, 0));
    map.integrate(wallScan(), Point3f(0.3F, 0.2F, 0.1F));
    return cellsOf(map);
  };
  const auto one = build(GetParam(), 1);
  const auto two = build(GetParam(), 2);
  ASSERT_FALSE(one.empty());
  EXPECT_EQ(one, two);  // bit for bit
}

TEST(FreeTraversal, ResultDoesNotDependOnTheThreadCount) {
  const auto build = [](int threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    options.free_traversal = true;
    options.max_range = 15.0;
    KernelMap map(0.1, options);
    map.integrate(roomScan(), Point3f(0, 0, 0));
    map.integrate(roomScan(), Point3f(0.3F, 0.2F, 0.1F));
    return cellsOf(map);
  };
  const auto one = build(1);
  ASSERT_GT(one.size(), 1000U);
  EXPECT_EQ(one, build(2));  // bit for bit: fixed-point sums do not depend on the order
}

// Rays whose hits share a voxel give one free capsule (free_bundles).
/// `levels`: free_bundle_levels (< 0: the default).
KernelMap mapOf(const PointCloud& points, bool bundles, double resolution = 0.1,
                double levels = -1.0) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  options.free_bundles = bundles;
  if (levels >= 0.0) options.free_bundle_levels = levels;
  KernelMap map(resolution, options);
  map.integrate(points, Point3f(0, 0, 0));
  map.integrate(points, Point3f(0.3F, 0.2F, 0.1F));
  return map;
}

double totalBeta(const KernelMap& map) {
  double sum = 0.0;
  for (const double b : map.evidence().beta) sum += b;
  return sum;
}

/// Cells that are clearly free or occupied (p beyond 0.5 +- 0.3) in map b are so in map a too,
/// but for under 1% of them (over 500 compared).
template <class Cells>
void expectTheSameShape(const Cells& a, const Cells& b) {
  std::map<std::uint64_t, double> other(b.begin(), b.end());
  std::size_t compared = 0, flipped = 0;
  for (const auto& [key, p] : a) {
    const auto it = other.find(key);
    if (it == other.end() || std::abs(it->second - 0.5) < 0.3) continue;
    ++compared;
    flipped += (p > 0.5) != (it->second > 0.5);
  }
  ASSERT_GT(compared, 500U);
  EXPECT_LT(static_cast<double>(flipped), 0.01 * static_cast<double>(compared));
}

/// Map a differs from map b (a model change), but not in its total occupied evidence (within
/// 2%) nor its shape (expectTheSameShape).
void expectAnotherMapOfTheSameShape(const KernelMap& a, const KernelMap& b) {
  double alpha_a = 0.0, alpha_b = 0.0;
  for (const double v : a.evidence().alpha) alpha_a += v;
  for (const double v : b.evidence().alpha) alpha_b += v;
  EXPECT_NE(cellsOf(a), cellsOf(b));
  EXPECT_NEAR(alpha_a / alpha_b, 1.0, 0.02);
  expectTheSameShape(cellsOf(a), cellsOf(b));
}

TEST(FreeBundles, AVoxelHitByOneRayGivesThatRaysCapsuleBitForBit) {
  // A wall's hits 0.31 m apart: one hit per voxel, nothing to bundle (in cubes: the tree above
  // them bundles their rays near the origin, FreeBundles.ATreeOfBundles...).
  PointCloud sparse;
  for (double y = -1.5; y <= 1.5; y += 0.31) {
    for (double z = -0.9; z <= 0.9; z += 0.31) {
      sparse.emplace_back(3.0F, static_cast<float>(y), static_cast<float>(z));
    }
  }
  const auto bundled = cellsOf(mapOf(sparse, true, 0.05, 0.0));
  ASSERT_GT(bundled.size(), 1000U);
  EXPECT_EQ(bundled, cellsOf(mapOf(sparse, false, 0.05)));
}

TEST(FreeBundles, RaysEndingInOneVoxelKeepTheirEvidenceAndTheMapsShape) {
  // The room's floor and wall at 0.2 m: several hits per voxel, bundled.
  const KernelMap bundled = mapOf(roomScan(), true, 0.2);
  const KernelMap each = mapOf(roomScan(), false, 0.2);
  EXPECT_NE(cellsOf(bundled), cellsOf(each));  // bundling happened
  // The same evidence per metre of ray: the total free evidence within 3%.
  EXPECT_NEAR(totalBeta(bundled) / totalBeta(each), 1.0, 0.03);
  // Cells that are clearly free or occupied in one map are so in the other.
  expectTheSameShape(cellsOf(bundled), cellsOf(each));
}

/// `scan` from two origins at 0.1 m with `options` (max range 15 m); the free visits into *visits.
KernelMap twoOriginsMap(const PointCloud& scan, KernelOptions options, std::size_t* visits) {
  options.max_range = 15.0;
  KernelMap map(0.1, options);
  *visits = 0;
  for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.3F, 0.2F, 0.1F)}) {
    *visits += map.integrate(scan, origin).free_visits;
  }
  return map;
}

// Where voxels are finer than free_bundle_m, the rays whose hits share
// a cube of that edge give one capsule: far fewer capsule visits at 0.1 m, the same evidence per
// metre of ray and the same map's shape; a cube no larger than a voxel is the voxel, bit for bit.
TEST(FreeBundles, CubesBundleTheRaysOfNeighbouringVoxels) {
  const auto run = [](double bundle_m, std::size_t* visits) {
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    options.free_bundle_m = bundle_m;
    return twoOriginsMap(roomScan(), options, visits);
  };
  std::size_t voxel_visits = 0, cube_visits = 0, same_visits = 0;
  const KernelMap voxels = run(0.0, &voxel_visits);
  const KernelMap cubes = run(0.2, &cube_visits);
  EXPECT_LT(static_cast<double>(cube_visits), 0.8 * static_cast<double>(voxel_visits));
  EXPECT_NEAR(totalBeta(cubes) / totalBeta(voxels), 1.0, 0.03);
  const auto b = cellsOf(voxels);
  expectTheSameShape(cellsOf(cubes), b);
  EXPECT_EQ(cellsOf(run(0.1, &same_visits)), b);
  EXPECT_EQ(same_visits, voxel_visits);
}

// The tree of bundles (free_bundle_levels, on by default) against the cubes' bundles alone:
// fewer capsule visits, the same evidence per metre of ray (within 3%) and the same map's
// shape; a scan of rays far apart (no bundle with siblings) is the same map bit for bit.
TEST(FreeBundles, ATreeOfBundlesKeepsTheEvidenceAndTheShapeWithFewerVisits) {
  const auto run = [](const PointCloud& scan, double levels, std::size_t* visits) {
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    options.free_bundle_levels = levels;
    return twoOriginsMap(scan, options, visits);
  };
  EXPECT_EQ(KernelOptions::defaults(KernelMethod::kAkimapRays).free_bundle_levels, 6.0);
  std::size_t flat_visits = 0, tree_visits = 0;
  const KernelMap flat = run(roomScan(), 0.0, &flat_visits);
  const KernelMap tree = run(roomScan(), 6.0, &tree_visits);
  EXPECT_LT(static_cast<double>(tree_visits), 0.85 * static_cast<double>(flat_visits));
  EXPECT_NEAR(totalBeta(tree) / totalBeta(flat), 1.0, 0.03);
  expectTheSameShape(cellsOf(tree), cellsOf(flat));
  // Eight rays 45 degrees apart: their cubes share no parent below the top levels, whose
  // segments (within 1/64 of the way) then hold one ray each.
  PointCloud apart;
  for (int k = 0; k < 8; ++k) {
    const double a = k * std::numbers::pi / 4.0;
    apart.emplace_back(static_cast<float>(6.0 * std::cos(a)), static_cast<float>(6.0 * std::sin(a)),
                       0.5F);
  }
  std::size_t a0 = 0, a6 = 0;
  const KernelMap apart_flat = run(apart, 0.0, &a0);
  const KernelMap apart_tree = run(apart, 6.0, &a6);
  std::size_t a1 = 0;
  const KernelMap apart_one = run(apart, 1.0, &a1);
  EXPECT_EQ(cellsOf(apart_one), cellsOf(apart_flat));
  EXPECT_EQ(a1, a0);
  // The top levels' cubes (6.4 and 12.8 m) bundle them near the origin: the same shape.
  expectTheSameShape(cellsOf(apart_tree), cellsOf(apart_flat));
}

// The fast path (each row's stretch; point kernels by per-axis squared offsets) against the
// plain one (every cell of each kernel's box, each kernel by Kernel::at). akimap_rays' hit
// kernels evaluated (hit_stencil_steps=0): the tabled ones are checked below.
/// Two room scans into a map by the fast path and one by the plain path (whole_boxes).
std::pair<KernelMap, KernelMap> fastAndPlainMaps(KernelOptions options, double resolution) {
  options.max_range = 15.0;
  KernelMap fast(resolution, options);
  options.whole_boxes = true;
  KernelMap plain(resolution, options);
  for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
    fast.integrate(roomScan(), origin);
    plain.integrate(roomScan(), origin);
  }
  return {std::move(fast), std::move(plain)};
}

TEST_P(KernelMapMethods, RowStretchesAndPointKernelsGiveTheWholeBoxesMapBitForBit) {
  for (const double resolution : {0.1, 0.07}) {
    KernelOptions options = KernelOptions::defaults(GetParam());
    options.hit_stencil_steps = 0.0;
    const auto [fast, plain] = fastAndPlainMaps(options, resolution);
    const auto a = cellsOf(fast);
    ASSERT_GT(a.size(), 1000U);
    EXPECT_EQ(a, cellsOf(plain)) << "resolution " << resolution;
  }
}

// akimap_rays' hit kernels read from tables (HitStencils) give the map of the same
// kernels evaluated cell by cell at their sub-positions (the plain path), to rounding.
TEST(HitStencils, TabledHitKernelsGiveTheEvaluatedMap) {
  for (const double steps : {1.0, 2.0, 4.0}) {
    for (const double resolution : {0.1, 0.07}) {
      KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
      options.hit_stencil_steps = steps;
      const auto [fast, plain] = fastAndPlainMaps(options, resolution);
      const KernelEvidence a = fast.evidence(), b = plain.evidence();
      SCOPED_TRACE("steps " + std::to_string(steps) + ", resolution " + std::to_string(resolution));
      ASSERT_GT(a.keys.size(), 1000U);
      ASSERT_EQ(a.keys, b.keys);
      for (std::size_t i = 0; i < a.keys.size(); ++i) {
        ASSERT_NEAR(a.alpha[i], b.alpha[i], 1e-6 * (1.0 + std::abs(b.alpha[i]))) << i;
        ASSERT_EQ(a.beta[i], b.beta[i]) << i;  // the free evidence is not tabled
      }
    }
  }
}

// hit_centre_pull moves a hit kernel's centre that share of the way to its voxel's centre
// (evaluated, and before the tables quantise it); the cell's own evidence stays at the hit.
TEST(HitStencils, CentrePullMovesTheHitKernelTowardItsVoxelsCentre) {
  KernelOptions o = KernelOptions::defaults(KernelMethod::kAkimapRays);
  const VoxelGrid grid(0.2);
  const std::vector<Eigen::Vector3d> hit = {{1.01, 0.02, -0.19}};  // voxel centre (1.1, 0.1, -0.1)
  const Eigen::Vector3d voxel_centre(1.1, 0.1, -0.1);
  for (const double pull : {0.0, 0.5, 1.0}) {
    o.hit_centre_pull = pull;
    std::vector<detail::Kernel> evaluated;
    detail::appendHitKernels(hit, nullptr, o, grid, nullptr, evaluated);
    ASSERT_EQ(evaluated.size(), 2U);  // the cell, then the kernel
    EXPECT_TRUE(evaluated[0].cell);
    EXPECT_LT((evaluated[0].x - hit[0]).norm(), 1e-12);
    EXPECT_LT((evaluated[1].x - (hit[0] + pull * (voxel_centre - hit[0]))).norm(), 1e-12) << pull;
    // Tabled at 2 steps: the hit is nearest its voxel's lower corner; from half way on, nearest
    // its centre.
    const detail::HitStencils halves(o.hit_length_voxels, 2, o.hit_kernel_weight, o.hit_weight,
                                     squaredKernel());
    std::vector<detail::Kernel> tabled;
    detail::appendHitKernels(hit, nullptr, o, grid, &halves, tabled);
    ASSERT_EQ(tabled.size(), 1U);
    const Eigen::Vector3d expected = pull < 0.5 ? Eigen::Vector3d(1.0, 0.0, -0.2) : voxel_centre;
    EXPECT_LT((tabled[0].x - expected).norm(), 1e-12) << pull;
  }
}

// The tables quantise a hit kernel's centre to its voxel's sub-positions (faces included) and
// merge the hits of one sub-position (with their cell's evidence); a map made so classifies as
// the kernels at the hits do, with the same total occupied evidence.
TEST(HitStencils, QuantiseCentresMergeHitsAndKeepTheMapsShape) {
  const KernelOptions o = KernelOptions::defaults(KernelMethod::kAkimapRays);
  const VoxelGrid grid(0.2);
  const detail::HitStencils halves(o.hit_length_voxels, 2, o.hit_kernel_weight, o.hit_weight,
                                   squaredKernel());
  ASSERT_TRUE(halves.usable());
  // Voxel [1.0, 1.2) x [0, 0.2) x [-0.2, 0): two hits nearest its lower corner, one nearest its
  // centre; one in the next voxel, nearest that one's lower corner.
  const std::vector<Eigen::Vector3d> hits = {
      {1.01, 0.02, -0.19}, {1.04, 0.04, -0.16}, {1.11, 0.09, -0.11}, {1.23, 0.03, -0.17}};
  std::vector<detail::Kernel> kernels;
  detail::appendHitKernels(hits, nullptr, o, grid, &halves, kernels);
  ASSERT_EQ(kernels.size(), 3U);
  EXPECT_EQ(kernels[0].weight, 2.0);
  EXPECT_EQ(kernels[1].weight, 1.0);
  EXPECT_EQ(kernels[2].weight, 1.0);
  EXPECT_EQ(kernels[0].stencil_key, kernels[1].stencil_key);
  EXPECT_NE(kernels[1].stencil_key, kernels[2].stencil_key);
  EXPECT_TRUE(kernels[0].x.isApprox(Eigen::Vector3d(1.0, 0.0, -0.2), 1e-12));
  EXPECT_TRUE(kernels[1].x.isApprox(Eigen::Vector3d(1.1, 0.1, -0.1), 1e-12));
  EXPECT_TRUE(kernels[2].x.isApprox(Eigen::Vector3d(1.2, 0.0, -0.2), 1e-12));
  // The centre's table: the cell's evidence at offset 0, |dx| < 2 voxels on its row.
  const std::int32_t centre = kernels[1].stencil;
  EXPECT_TRUE(halves.centreOf(centre).isApprox(Eigen::Vector3d::Constant(0.5), 1e-12));
  EXPECT_NEAR(halves.row(centre, 0, 0)[halves.reach()], o.hit_kernel_weight + o.hit_weight, 1e-12);
  EXPECT_NEAR(halves.row(centre, 0, 0)[halves.reach() + 1],
              o.hit_kernel_weight * squaredKernel()(1.0 / 4.0), 1e-12);
  EXPECT_EQ(halves.rowExtent(centre, 0, 0), std::make_pair(-1, 1));
  // One step: the corners; the third hit is nearest the voxel's (1.2, 0, -0.2) corner.
  const detail::HitStencils corners(o.hit_length_voxels, 1, o.hit_kernel_weight, o.hit_weight,
                                    squaredKernel());
  kernels.clear();
  detail::appendHitKernels(hits, nullptr, o, grid, &corners, kernels);
  ASSERT_EQ(kernels.size(), 3U);
  EXPECT_EQ(kernels[0].weight, 2.0);
  EXPECT_TRUE(kernels[1].x.isApprox(Eigen::Vector3d(1.2, 0.0, -0.2), 1e-12));
  EXPECT_TRUE(kernels[2].x.isApprox(Eigen::Vector3d(1.2, 0.0, -0.2), 1e-12));
  EXPECT_NE(kernels[1].stencil_key, kernels[2].stencil_key);
  // Without tables: a cell kernel and a kernel per hit.
  kernels.clear();
  detail::appendHitKernels(hits, nullptr, o, grid, nullptr, kernels);
  EXPECT_EQ(kernels.size(), 8U);

  for (const double resolution : {0.1, 0.2}) {
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    options.max_range = 15.0;
    KernelMap tabled(resolution, options);
    options.hit_stencil_steps = 0.0;
    KernelMap evaluated(resolution, options);
    for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
      tabled.integrate(roomScan(), origin);
      evaluated.integrate(roomScan(), origin);
    }
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    expectAnotherMapOfTheSameShape(tabled, evaluated);
  }
}

// A voxel of 2 hits (shared_fit_min_hits): still a kernel per hit, their shape fitted once; the
// map classifies as with a fit per hit.
TEST(AkimapRays, VoxelsOfTwoHitsShareOneFitAndKeepTheMapsShape) {
  for (const double resolution : {0.1, 0.07}) {  // (at 0.2 m every voxel of the room has 3+)
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    ASSERT_EQ(options.shared_fit_min_hits, 2.0);
    options.max_range = 15.0;
    options.fit_cube_m = 0.0;  // a fit per voxel (a cube's fit is at its fullest voxel's mean)
    KernelMap shared(resolution, options);
    options.shared_fit_min_hits = 0.0;
    KernelMap each(resolution, options);
    for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
      EXPECT_EQ(shared.integrate(roomScan(), origin).samples,
                each.integrate(roomScan(), origin).samples);
    }
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    expectAnotherMapOfTheSameShape(shared, each);
  }
}

// fit_cube_m: the kernels of every voxel of a cube have the shape that a fit per voxel gives
// the cube's fullest voxel (one of them, where several hold as many hits), each at its own
// hits; the map classifies as with a fit per voxel.
TEST(AkimapRays, VoxelsOfACubeShareTheFitOfItsFullestVoxel) {
  for (const double resolution : {0.1, 0.05}) {
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    ASSERT_EQ(options.fit_cube_m, 0.4);
    options.max_range = 15.0;
    KernelOptions each_options = options;
    each_options.fit_cube_m = 0.0;
    const VoxelGrid grid(resolution);
    const Eigen::Vector3d origin(0.1, -0.2, 0.05);
    std::vector<Sample> samples;
    for (const Point3f& p : roomScan()) {
      Sample s;
      s.x = p.cast<double>();
      s.range = (s.x - origin).norm();
      s.occupied = true;
      if (s.range <= options.max_range) samples.push_back(s);
    }
    std::vector<std::uint32_t> hits(samples.size());
    for (std::uint32_t i = 0; i < hits.size(); ++i) hits[i] = i;
    detail::SampleIndex::Storage storage;
    const detail::SampleIndex index(samples, std::max(resolution, 0.25 * options.search_max),
                                    std::size_t{1} << 21, storage);
    struct Run {
      std::vector<detail::Kernel> kernels;
      std::vector<RayStop> stops;
      std::vector<Eigen::Vector3d> means;
      std::vector<double> counts;
    };
    const auto run = [&](const KernelOptions& o) {
      Run r;
      r.stops.resize(hits.size());
      detail::adaptiveVoxelKernels(grid, o, samples, hits, index, origin, r.kernels, r.stops,
                                   r.means, r.counts);
      return r;
    };
    const Run shared = run(options), each = run(each_options);
    ASSERT_EQ(shared.kernels.size(), each.kernels.size());
    // Each kernel's voxel and cube, and each voxel's hits (the counts of its kernels).
    const int cube_voxels = static_cast<int>(std::lround(options.fit_cube_m / resolution));
    std::map<std::uint64_t, double> hits_of_voxel;
    std::vector<std::uint64_t> voxel_of(each.kernels.size()), cube_of(each.kernels.size());
    for (std::size_t k = 0; k < each.kernels.size(); ++k) {
      const VoxelKey key = *grid.pointToKey(each.means[k].cast<float>());
      voxel_of[k] = key.packed();
      cube_of[k] = VoxelKey{static_cast<std::uint16_t>(key.x / cube_voxels),
                            static_cast<std::uint16_t>(key.y / cube_voxels),
                            static_cast<std::uint16_t>(key.z / cube_voxels)}
                       .packed();
      hits_of_voxel[voxel_of[k]] += each.counts[k];
    }
    std::map<std::uint64_t, double> most_in_cube;
    std::map<std::uint64_t, std::set<std::uint64_t>> voxels_of_cube;
    for (std::size_t k = 0; k < each.kernels.size(); ++k) {
      most_in_cube[cube_of[k]] = std::max(most_in_cube[cube_of[k]], hits_of_voxel[voxel_of[k]]);
      voxels_of_cube[cube_of[k]].insert(voxel_of[k]);
    }
    std::size_t shared_cubes = 0, moved = 0;
    for (const auto& [cube, voxels] : voxels_of_cube) shared_cubes += voxels.size() > 1;
    EXPECT_GT(shared_cubes, 50U);
    std::map<std::uint64_t, Eigen::Matrix3d> shape_of_cube;
    for (std::size_t k = 0; k < each.kernels.size(); ++k) {
      const detail::Kernel& s = shared.kernels[k];
      ASSERT_EQ(s.x, each.kernels[k].x);  // at its own hits or mean
      ASSERT_EQ(s.weight, each.kernels[k].weight);
      const auto [it, first] = shape_of_cube.emplace(cube_of[k], s.h_inverse);
      ASSERT_EQ(it->second, s.h_inverse) << "two shapes in one cube";
      if (!first) continue;
      // The cube's shape is a fullest voxel's own fit.
      bool found = false;
      for (std::size_t j = 0; j < each.kernels.size(); ++j) {
        found |= cube_of[j] == cube_of[k] &&
                 hits_of_voxel[voxel_of[j]] == most_in_cube[cube_of[k]] &&
                 each.kernels[j].h_inverse == s.h_inverse;
      }
      ASSERT_TRUE(found) << "kernel " << k;
    }
    for (std::size_t k = 0; k < each.kernels.size(); ++k) {
      moved += shared.kernels[k].h_inverse != each.kernels[k].h_inverse;
    }
    EXPECT_GT(moved, 50U);
    // And the map: fewer fits, the same classification.
    KernelMap shared_map(resolution, options), each_map(resolution, each_options);
    for (const Point3f& o : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
      shared_map.integrate(roomScan(), o);
      each_map.integrate(roomScan(), o);
    }
    expectAnotherMapOfTheSameShape(shared_map, each_map);
  }
}

INSTANTIATE_TEST_SUITE_P(All, KernelMapMethods,
                         ::testing::Values(KernelMethod::kAkimap, KernelMethod::kBgk,
                                           KernelMethod::kBgkl, KernelMethod::kAkimapRays),
                         [](const auto& param_info) {
                           return std::string(kernelMethodName(param_info.param));
                         });

// akimap_rays' free evidence by one capsule per ray. Rays cut at max range carry free
// evidence only (no hit, no tip, no occupied kernel), so each voxel's beta is exactly the sum of
// its distances' kernels: checked against a plain reference (every addressable voxel of each
// ray's box, sparseKernel, double sums), for rays from `origin`.
void expectCutRaysGiveEveryVoxelInReachTheKernelOfItsDistance(const Point3f& origin) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  ASSERT_TRUE(options.free_traversal);
  options.max_range = 4.0;
  options.free_bundle_levels = 0.0;  // each ray its own capsule (the tree bundles cut rays)
  const double resolution = 0.1;
  KernelMap map(resolution, options);
  PointCloud points;
  for (int i = 0; i < 60; ++i) {  // directions over a cone, all ending beyond max range
    const double a = 0.1 * i, b = 0.05 * (i % 7) - 0.15;
    points.emplace_back(origin.x() + static_cast<float>(9.0 * std::cos(a)),
                        origin.y() + static_cast<float>(9.0 * std::sin(a)),
                        origin.z() + static_cast<float>(9.0 * b));
  }
  map.integrate(points, origin);
  const double joints = 1.0 + 2.0 * options.length_scale / 3.0 / options.free_step;
  // Capsules reach free_reach of their radius, their weight scaled by the evidence share there
  // (the midpoint rule's integral of k(x) x, as FreeTraversal states it).
  ASSERT_LT(options.free_reach, 1.0);
  double inside = 0.0, all = 0.0;
  for (int s = 0; s < 100000; ++s) {
    const double x = (s + 0.5) / 100000;
    all += sparseKernel(x) * x;
    if (x < options.free_reach) inside += sparseKernel(x) * x;
  }
  const double compensation = all / inside;
  EXPECT_GT(compensation, 1.0);
  EXPECT_LT(compensation, 1.01);
  std::map<std::uint64_t, double> beta;
  const VoxelGrid& grid = map.grid();
  for (const Point3f& p : points) {
    const Eigen::Vector3d o = origin.cast<double>();
    const Eigen::Vector3d dir = (p.cast<double>() - o).normalized();
    const Eigen::Vector3d end = o + options.max_range * dir;
    // Every voxel of the segment's bounding box, widened by the kernel's reach.
    test::forEachVoxelOfSegmentBox(
        grid, o, end, options.length_scale, [&](const VoxelKey& k, double d) {
          if (d >= options.free_reach * options.length_scale) return;
          const double w =
              options.sf2 * joints * compensation * sparseKernel(d / options.length_scale);
          if (w > 0.0) beta[k.packed()] += w;
        });
  }
  ASSERT_GT(beta.size(), 500U);
  std::size_t checked = 0;
  map.forEachKnown([&](const VoxelKey& k, double p) {
    const auto it = beta.find(k.packed());
    ASSERT_NE(it, beta.end()) << "a voxel no ray reaches has evidence";
    const double measured = options.prior / p - 2.0 * options.prior;  // p = a0 / (2 a0 + beta)
    EXPECT_NEAR(measured, it->second, 1e-4 * std::max(1.0, it->second));
    ++checked;
  });
  // Voxels at the very edge of the reach (d within rounding of the radius) may differ.
  EXPECT_GE(checked, beta.size() - beta.size() / 200);
  EXPECT_LE(checked, beta.size());
}

TEST(FreeTraversal, CutRaysGiveEveryVoxelInReachTheKernelOfItsDistance) {
  expectCutRaysGiveEveryVoxelInReachTheKernelOfItsDistance(Point3f(0.03F, -0.02F, 0.01F));
}

// At the addressable range's edge (0.1 m voxels: 3276.8 m), where some capsules leave it along
// their slices' axis and others across it (the rasteriser's clamped keys).
TEST(FreeTraversal, CutRaysAtTheEdgeOfTheAddressableRangeGiveTheKernelOfTheirDistance) {
  expectCutRaysGiveEveryVoxelInReachTheKernelOfItsDistance(Point3f(3276.72F, -0.02F, 0.01F));
}

// The free sums are 32-bit fixed point at a step chosen per scan: a voxel crossed by thousands of
// rays (each near a unit of evidence; the int32 range at 2^-30 holds 2) keeps its sum. The same
// ray 5,000 times gives 5,000 times one ray's evidence in every voxel, to the coarser step's
// rounding, where a fixed 2^-30 step would wrap.
TEST(FreeTraversal, ThousandsOfRaysThroughOneVoxelKeepTheirSums) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 1.5;
  const auto betas = [&](int copies) {
    KernelMap map(0.1, options);
    PointCloud points(static_cast<std::size_t>(copies), Point3f(6.0F, 1.0F, 0.5F));  // cut
    map.integrate(points, Point3f(0.02F, 0.01F, -0.03F));
    std::map<std::uint64_t, double> out;
    const KernelEvidence e = map.evidence();
    for (std::size_t i = 0; i < e.keys.size(); ++i) out[e.keys[i].packed()] = e.beta[i];
    return out;
  };
  const auto one = betas(1);
  const auto many = betas(5000);
  ASSERT_GT(one.size(), 50U);
  ASSERT_EQ(one.size(), many.size());
  for (const auto& [key, b] : one) {
    ASSERT_TRUE(many.count(key));
    EXPECT_GT(many.at(key), 0.0);
    // The step is at least 2^31 / (4 * total weight), total weight about 2 * 5,000 (weights and
    // a unit of rounding per extent): each ray's contribution rounds by at most 9.4e-6, the same
    // way for all 5,000 identical rays.
    EXPECT_NEAR(many.at(key), 5000.0 * b, 5000.0 * 9.4e-6 + 1e-5 * 5000.0 * b);
  }
}

// The fast path changes the model a little (one capsule per ray, its joints as a mean; one
// kernel per voxel of many hits): on a room with grazing rays it classifies as the segment kernels
// do almost everywhere.
TEST(FreeTraversal, AgreesWithTheSegmentKernelsOnARoom) {
  for (const double resolution : {0.2, 0.1}) {
    KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
    options.max_range = 15.0;
    KernelMap fast(resolution, options);
    options.free_traversal = false;
    options.aggregate_hits = false;
    KernelMap plain(resolution, options);
    for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
      fast.integrate(roomScan(), origin);
      plain.integrate(roomScan(), origin);
    }
    std::size_t both = 0, agree = 0;
    double sum_abs = 0.0;
    plain.forEachKnown([&](const VoxelKey& k, double p) {
      const auto q = fast.probability(k);
      if (!q) return;
      ++both;
      agree += (p > 0.5) == (*q > 0.5);
      sum_abs += std::abs(p - *q);
    });
    SCOPED_TRACE("resolution " + std::to_string(resolution));
    ASSERT_GT(both, 1000U);
    EXPECT_GT(static_cast<double>(both), 0.85 * static_cast<double>(plain.knownCells()));
    EXPECT_GT(static_cast<double>(agree), 0.97 * static_cast<double>(both));
    EXPECT_LT(sum_abs / static_cast<double>(both), 0.08);
  }
}

// A kernel map evicts whole blocks (evidence and memory); what stays is the map
// without those blocks, bit for bit.
TEST(KernelMapEviction, KeepsExactlyTheBlocksItIsToldToKeep) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  KernelMap evicted(0.1, options), whole(0.1, options);
  for (KernelMap* m : {&evicted, &whole}) m->integrate(roomScan(), Point3f(0, 0, 0));
  const auto keep = [](const Point3f& centre) { return centre.x() < 2.0F; };
  EXPECT_GT(evicted.evictBlocks(keep), 0U);
  std::vector<std::pair<std::uint64_t, double>> expected;
  whole.forEachKnown([&](const VoxelKey& k, double p) {
    if (keep(block::centreOf(whole.grid(), block::blockOf(k))))
      expected.emplace_back(k.packed(), p);
  });
  std::sort(expected.begin(), expected.end());
  ASSERT_GT(expected.size(), 1000U);
  EXPECT_EQ(cellsOf(evicted), expected);
  EXPECT_LT(evicted.knownCells(), whole.knownCells());
}

// A scan's buffers are released as its stages end, so between scans a kernel
// map holds its evidence and nothing else: what a map restored from that evidence (which never
// integrated a scan) holds.
TEST(KernelMapMemory, BetweenScansAMapHoldsOnlyItsEvidence) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  KernelMap map(0.1, options);
  for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
    map.integrate(roomScan(), origin);
    KernelMap restored(0.1, options);
    ASSERT_TRUE(restored.restore(map.evidence()).has_value());
    ASSERT_EQ(restored.knownCells(), map.knownCells());
    EXPECT_LE(static_cast<double>(map.memoryBytes()),
              1.05 * static_cast<double>(restored.memoryBytes()) + 65536.0);
  }
}

// Every evidence block holds a known cell. A block that a kernel's box overlapped but
// none of whose cells it reached was kept, empty, where the published map (and so eviction)
// never saw it: on a long drive they piled up (RSS +3.7 MiB per 100 scans at a flat map).
TEST(KernelMapMemory, EveryEvidenceBlockHoldsAKnownCell) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  KernelMap map(0.1, options);
  map.integrate(roomScan(), Point3f(0, 0, 0));
  map.integrate(roomScan(), Point3f(0.4F, -0.3F, 0.2F));
  std::set<std::uint64_t> blocks;
  map.forEachKnown([&](const VoxelKey& k, double) { blocks.insert(block::blockOf(k)); });
  ASSERT_GT(blocks.size(), 10U);
  EXPECT_EQ(map.evictBlocks([](const Point3f&) { return false; }), blocks.size());
  EXPECT_EQ(map.knownCells(), 0U);
}

// A kernel map whose evidence lives in a GridMap's block entries holds the
// same evidence as one with a store of its own, bit for bit, through a published version; the
// grid's eviction and reset take the evidence with the cells (no second index to keep in step),
// and the grid's memory counts it.
TEST(KernelMapInAGrid, SharesTheGridsEntriesAndLosesEvidenceWithItsBlocks) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  GridMap grid(0.1, SensorModel{});
  const std::size_t empty_bytes = grid.memoryBytes();
  KernelMap shared(0.1, options, &grid.writerStore()), own(0.1, options);
  const auto publishTouched = [&](const std::vector<BlockCells>& touched) {
    (void)grid.assignBlocks(touched, [&](std::uint64_t key, const block::BlockMask& cells,
                                         std::array<float, block::kVoxels>& values) {
      shared.blockLogOdds(key, cells, values);
    });
    (void)grid.publishVersion();  // versioned from here: writes copy the published nodes
  };
  for (const Point3f& origin : {Point3f(0, 0, 0), Point3f(0.4F, -0.3F, 0.2F)}) {
    std::vector<BlockCells> touched;
    shared.integrate(roomScan(), origin, &touched);
    own.integrate(roomScan(), origin);
    publishTouched(touched);
  }
  const KernelEvidence a = shared.evidence(), b = own.evidence();
  ASSERT_GT(a.keys.size(), 1000U);
  EXPECT_EQ(a.keys, b.keys);
  EXPECT_EQ(a.alpha, b.alpha);
  EXPECT_EQ(a.beta, b.beta);
  // Every block with evidence is a published block, and the other way round.
  std::set<std::uint64_t> published;
  grid.forEachKnown([&](const VoxelKey& k, float) { published.insert(block::blockOf(k)); });
  EXPECT_EQ(grid.writerStore().evidenceBlocks(), published.size());
  EXPECT_EQ(grid.knownCells(), shared.knownCells());
  EXPECT_GT(grid.memoryBytes(),
            empty_bytes + grid.writerStore().evidenceBlocks() * sizeof(BlockEvidence));
  EXPECT_LT(shared.memoryBytes(), grid.memoryBytes() / 4);  // its buffers only
  // The grid evicts: the evidence goes with its blocks, as the offline map's own eviction.
  const auto keep = [](const Point3f& centre) { return centre.x() < 2.0F; };
  EXPECT_GT(grid.evictBlocks(keep).blocks, 0U);
  EXPECT_GT(own.evictBlocks(keep), 0U);
  EXPECT_EQ(cellsOf(shared), cellsOf(own));
  EXPECT_EQ(grid.knownCells(), shared.knownCells());
  // The next scan on both: the same again.
  std::vector<BlockCells> touched;
  shared.integrate(roomScan(), Point3f(0.2F, 0.1F, 0), &touched);
  own.integrate(roomScan(), Point3f(0.2F, 0.1F, 0));
  publishTouched(touched);
  EXPECT_EQ(cellsOf(shared), cellsOf(own));
  grid.clear();
  EXPECT_EQ(shared.knownCells(), 0U);
  EXPECT_EQ(grid.writerStore().evidenceBlocks(), 0U);
}

TEST(KernelMethodNames, ParseAndReject) {
  EXPECT_EQ(*parseKernelMethod("bgkl"), KernelMethod::kBgkl);
  EXPECT_EQ(*parseKernelMethod("akimap_rays"), KernelMethod::kAkimapRays);
  const auto bad = parseKernelMethod("gmm");
  ASSERT_FALSE(bad.has_value());
  EXPECT_NE(bad.error().message.find("akimap"), std::string::npos);
}

TEST(OccupancySamples, RandomFreeSamplesAreReproducibleAndOnePerInterval) {
  const PointCloud points = {Point3f(2.2F, 0, 0), Point3f(0, 40.0F, 0)};
  SamplingOptions o;
  o.max_range = 10.0;
  const auto a = makeSamples(points, Point3f(0, 0, 0), o, 3);
  const auto b = makeSamples(points, Point3f(0, 0, 0), o, 3);
  const auto c = makeSamples(points, Point3f(0, 0, 0), o, 4);
  // Ray 1: 1 occupied + 4 free (2.2 m / 0.5 m); ray 2 is cut at 10 m: 20 free, no occupied.
  ASSERT_EQ(a.size(), 25U);
  EXPECT_EQ(std::count_if(a.begin(), a.end(), [](const Sample& s) { return s.occupied; }), 1);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].x, b[i].x);
  EXPECT_NE(a[1].x, c[1].x);  // another scan draws other points
  for (int k = 0; k < 4; ++k) {
    EXPECT_GE(a[1 + k].range, 0.5 * k);
    EXPECT_LT(a[1 + k].range, 0.5 * (k + 1));
  }
}

TEST(AkimapRays, GrazingRaysLeaveTheFloorOccupiedAndFreeSpaceAboveItFree) {
  KernelOptions options = KernelOptions::defaults(KernelMethod::kAkimapRays);
  options.max_range = 15.0;
  KernelMap rays(0.1, options);
  rays.integrate(roomScan(), Point3f(0, 0, 0));
  const auto at = [&](float x, float y, float z) {
    return rays.probability(*rays.grid().pointToKey(Point3f(x, y, z))).value_or(0.5);
  };
  // Behind the wall the floor is not seen; in front of it, rays meet the floor at 22 to 67 deg
  // from it, and up to 1.3 m short of the wall at the height of the floor under it.
  for (const float x : {1.05F, 1.55F, 2.05F, 2.45F}) {
    EXPECT_GT(at(x, 0.05F, -1.15F), 0.5) << "floor at x " << x;
    EXPECT_LT(at(x, 0.05F, -0.65F), 0.5) << "free 0.5 m above the floor at x " << x;
  }
  EXPECT_GT(at(3.02F, 0.02F, 0.02F), 0.5);
  EXPECT_LT(at(2.55F, 0.02F, 0.02F), 0.5);  // free 0.45 m in front of the wall
}

TEST(RaySegments, CoverEachRayToItsStopThenTheTip) {
  const PointCloud points = {Point3f(2.0F, 0, 0), Point3f(0, 40.0F, 0), Point3f(0, 0, 0)};
  const std::vector<RayStop> stops = {{0.25, 0.05}};
  const auto segments = makeRaySegments(points, Point3f(0, 0, 0), 0.3, 10.0, stops);
  // Ray 1: [0, 1.75] in 6 equal pieces, then the tip [1.75, 1.95]; ray 2 is cut at 10 m:
  // 34 pieces, no tip; the zero-length ray gives nothing.
  ASSERT_EQ(segments.size(), 6U + 1U + 34U);
  double end = 0.0;
  for (int i = 0; i < 6; ++i) {
    EXPECT_TRUE(segments[i].segment);
    EXPECT_FALSE(segments[i].tip);
    EXPECT_NEAR(segments[i].x.x(), end, 1e-12);
    end = segments[i].to.x();
    EXPECT_LE(segments[i].to.x() - segments[i].x.x(), 0.3 + 1e-12);
  }
  EXPECT_NEAR(end, 1.75, 1e-12);
  EXPECT_TRUE(segments[6].tip);
  EXPECT_NEAR(segments[6].x.x(), 1.75, 1e-12);
  EXPECT_NEAR(segments[6].to.x(), 1.95, 1e-12);
  EXPECT_NEAR(segments.back().to.y(), 10.0, 1e-9);
  EXPECT_FALSE(segments.back().tip);
  // No tip when it would not pass the free part's end.
  const std::vector<RayStop> no_tip = {{0.25, 0.25}};
  EXPECT_EQ(makeRaySegments({Point3f(2.0F, 0, 0)}, Point3f(0, 0, 0), 0.3, 10.0, no_tip).size(), 6U);
}

TEST(NearHits, SaysYesWithinReachOfEveryHitAndNoFarAway) {
  const std::vector<Eigen::Vector3d> hits = {{0, 0, 0}, {5.3, -2.1, 0.7}};
  const NearHits near(hits, 0.5);
  for (const auto& h : hits) {
    for (int i = 0; i < 27; ++i) {
      const Eigen::Vector3d d(0.49 * (i % 3 - 1), 0.49 * (i / 3 % 3 - 1), 0.49 * (i / 9 - 1));
      EXPECT_TRUE(near(h + d));
    }
  }
  EXPECT_FALSE(near(Eigen::Vector3d(2.6, -1.0, 0.3)));
  EXPECT_FALSE(near(Eigen::Vector3d(-3, 0, 0)));
  EXPECT_FALSE(NearHits({}, 0.5)(Eigen::Vector3d::Zero()));
}

TEST(KernelSettings, ApplyKnownNamesAndRejectTheRest) {
  KernelOptions o = KernelOptions::defaults(KernelMethod::kAkimapRays);
  ASSERT_TRUE(applySettings(o, {"sf2=0.7", "free_margin=0", "hit_weight=2"}));
  EXPECT_DOUBLE_EQ(o.sf2, 0.7);
  EXPECT_DOUBLE_EQ(o.free_margin, 0.0);
  EXPECT_DOUBLE_EQ(o.hit_weight, 2.0);
  ASSERT_TRUE(applySettings(o, {"free_reach=1"}));
  EXPECT_DOUBLE_EQ(o.free_reach, 1.0);
  ASSERT_TRUE(applySettings(o, {"hit_stencil_steps=0", "hit_stencil_steps=3"}));
  EXPECT_DOUBLE_EQ(o.hit_stencil_steps, 3.0);
  ASSERT_TRUE(applySettings(o, {"hit_centre_pull=0", "hit_centre_pull=0.5"}));
  EXPECT_DOUBLE_EQ(o.hit_centre_pull, 0.5);
  for (const char* bad :
       {"sf2", "nope=1", "sf2=abc", "sf2=1x", "sf2=-1", "sf2=0", "sf2=nan", "free_reach=0",
        "free_reach=1.01", "hit_stencil_steps=5", "hit_stencil_steps=1.5", "hit_stencil_steps=-1",
        "hit_centre_pull=1.5", "hit_centre_pull=-0.1"}) {
    EXPECT_FALSE(applySettings(o, {bad})) << bad;
  }
  EXPECT_DOUBLE_EQ(o.sf2, 0.7);
}

}  // namespace
}  // namespace densemap::kernel
