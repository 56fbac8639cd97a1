// The mapping engine alone (core computes): no thread, no queue, no counters; each
// call runs every stage on the caller's thread and publishes a version.
#include "densemap/pipeline/engine.hpp"

#include <gtest/gtest.h>

#include <random>
#include <thread>

#include "densemap/map/grid_map.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

/// The engine's options: every default but the map's resolution and range.
PipelineOptions engineOptions(double resolution_m, double max_range_m) {
  PipelineOptions o;
  o.resolution_m = resolution_m;
  o.max_range_m = max_range_m;
  return o;
}

RawScan rawScan(std::uint64_t seq) {
  const PointCloud cloud = test::adversarialScan(0.2, Point3f::Zero(), 3000, 6.0, 1000 + seq);
  RawScan raw;
  raw.sensor_id = "front";
  raw.seq = seq;
  raw.stamp_ns = 1000 * static_cast<std::int64_t>(seq);
  raw.t_world_sensor = {0.1 * static_cast<double>(seq), 0.05, 0.3};
  for (const auto& p : cloud) raw.xyz.insert(raw.xyz.end(), {p.x(), p.y(), p.z()});
  return raw;
}

TEST(Engine, IntegratesOnTheCallersThreadAsTheOfflineIntegratorDoes) {
  auto engine = Engine::create(engineOptions(0.2, 5.0));
  ASSERT_TRUE(engine);
  GridMap offline(0.2, SensorModel{});
  Integrator integrator({.max_range_m = 5.0});
  const auto caller = std::this_thread::get_id();
  auto seen = (*engine)->view();
  for (std::uint64_t seq = 1; seq <= 4; ++seq) {
    const RawScan raw = rawScan(seq);
    auto result = (*engine)->integrate(raw);
    ASSERT_TRUE(result) << result.error().message;
    EXPECT_EQ(std::this_thread::get_id(), caller);
    EXPECT_TRUE(result->from_scan);
    EXPECT_EQ(result->sensor_id, "front");
    EXPECT_EQ(result->scan_seq, seq);
    EXPECT_EQ(result->stamp_ns, raw.stamp_ns);
    EXPECT_EQ(result->base_version, seen->version());
    EXPECT_EQ(result->new_version, seq);
    EXPECT_FALSE(result->written_blocks.empty());
    const Scan scan = *validateScan(raw, ScanLimits{});
    integrator.integrate(offline, scan.pointsWorld(), scan.originWorld());
    seen = (*engine)->view();
    EXPECT_EQ(seen->version(), seq);
    std::size_t wrong = 0;
    offline.forEachKnown([&](const VoxelKey& k, float v) { wrong += seen->logOdds(k) != v; });
    EXPECT_EQ(wrong, 0U);
    EXPECT_EQ(seen->knownCells(), offline.knownCells());
  }
}

TEST(Engine, ARejectedScanSaysWhyAndPublishesNothing) {
  PipelineOptions options = engineOptions(0.2, -1.0);
  options.limits.max_points = 2000;
  auto engine = Engine::create(options);
  ASSERT_TRUE(engine);
  const auto before = (*engine)->view();
  const auto too_many = (*engine)->integrate(rawScan(1));  // 3000 points
  ASSERT_FALSE(too_many);
  EXPECT_EQ(too_many.error().reason, RejectReason::kTooManyPoints);
  RawScan nan = rawScan(2);
  nan.xyz.resize(300);
  nan.xyz[5] = std::numeric_limits<float>::quiet_NaN();
  const auto non_finite = (*engine)->integrate(nan);
  ASSERT_FALSE(non_finite);
  EXPECT_EQ(non_finite.error().reason, RejectReason::kNonFinitePoint);
  EXPECT_EQ((*engine)->view(), before);
}

TEST(Engine, ACommandWithChangesPublishesAVersionAndOneWithoutDoesNot) {
  auto engine = Engine::create(engineOptions(0.2, 5.0));
  ASSERT_TRUE(engine);
  ASSERT_TRUE((*engine)->integrate(rawScan(1)));
  IntegrationResult quiet;
  const auto noop = (*engine)->command(
      [](OccupancyMap&, CellChanges&) -> Expected<std::string> { return std::string("ok"); },
      quiet);
  ASSERT_TRUE(noop);
  EXPECT_EQ((*engine)->view()->version(), 1U);
  IntegrationResult cleared;
  const auto reset = (*engine)->command(
      [](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
        const VoxelKey lo = *map.grid().pointToKey(Point3f(-20, -20, -20));
        const VoxelKey hi = *map.grid().pointToKey(Point3f(20, 20, 20));
        map.clearBox(lo, hi, &changes);
        return std::string("cleared");
      },
      cleared);
  ASSERT_TRUE(reset);
  EXPECT_EQ(*reset, "cleared");
  EXPECT_FALSE(cleared.from_scan);
  EXPECT_EQ(cleared.base_version, 1U);
  EXPECT_EQ(cleared.new_version, 2U);
  EXPECT_EQ((*engine)->view()->knownCells(), 0U);
}

// Spatial shards: two engines whose boxes split space at x = 0.5 m (inside a block: a block
// belongs to the box its centre lies in, so the east shard keeps cells west of its box) together
// hold, cell for cell, the map of one engine without a box, and each traverses only the rays
// that reach its blocks.
TEST(Engine, ShardsWhoseBoxesTileSpaceTogetherHoldTheMapOfOneAndEachTraversesFewerRays) {
  auto single = Engine::create(engineOptions(0.2, 5.0));
  PipelineOptions west = engineOptions(0.2, 5.0), east = west;
  west.bounds = {{Point3f(-1000, -1000, -1000), Point3f(0.5, 1000, 1000)}};
  east.bounds = {{Point3f(0.5, -1000, -1000), Point3f(1000, 1000, 1000)}};
  auto shard_west = Engine::create(west);
  auto shard_east = Engine::create(east);
  ASSERT_TRUE(single && shard_west && shard_east);
  std::size_t rays_single = 0, rays_west = 0, rays_east = 0;
  for (std::uint64_t seq = 1; seq <= 4; ++seq) {
    RawScan raw = rawScan(seq);
    raw.t_world_sensor = {-7.5 + 5.0 * static_cast<double>(seq - 1), 0.05, 0.3};
    auto a = (*single)->integrate(raw);
    auto w = (*shard_west)->integrate(raw);
    auto e = (*shard_east)->integrate(raw);
    ASSERT_TRUE(a && w && e);
    rays_single += a->stats.points;
    rays_west += w->stats.points;
    rays_east += e->stats.points;
  }
  const auto whole = (*single)->view();
  const auto west_view = (*shard_west)->view();
  const auto east_view = (*shard_east)->view();
  std::size_t wrong = 0, in_both = 0;
  whole->forEachKnown([&](const VoxelKey& k, float v) {
    const auto w = west_view->logOdds(k), e = east_view->logOdds(k);
    in_both += w.has_value() && e.has_value();
    wrong += (w.has_value() ? *w : e.value_or(0.0F)) != v || (!w && !e);
  });
  EXPECT_EQ(wrong, 0U);
  EXPECT_EQ(in_both, 0U);
  EXPECT_EQ(west_view->knownCells() + east_view->knownCells(), whole->knownCells());
  EXPECT_GT(west_view->knownCells(), whole->knownCells() / 5);
  EXPECT_GT(east_view->knownCells(), whole->knownCells() / 5);
  // Each shard pays for its share: fewer rays than the whole, and not every ray twice.
  EXPECT_LT(rays_west, rays_single * 3 / 4);
  EXPECT_LT(rays_east, rays_single * 3 / 4);
}

TEST(Engine, SegmentMeetsBoxAgreesWithDenseSampling) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-3.0F, 3.0F);
  const Point3f lo(-1.0F, -0.5F, -0.25F), hi(1.0F, 0.5F, 0.25F);
  const auto inside = [&](const Point3f& p, float eps) {
    return (p.array() >= lo.array() - eps).all() && (p.array() <= hi.array() + eps).all();
  };
  int met = 0;
  for (int i = 0; i < 2000; ++i) {
    Point3f from(u(rng), u(rng), u(rng)), to(u(rng), u(rng), u(rng));
    if (i % 10 == 0) to.x() = from.x();  // parallel to a slab
    bool sampled = false, near = false;
    for (int s = 0; s <= 20000; ++s) {
      const Point3f p = from + (to - from) * (static_cast<float>(s) / 20000.0F);
      sampled = sampled || inside(p, 0.0F);
      near = near || inside(p, 1e-3F);
    }
    const bool meets = segmentMeetsBox(from, to, lo, hi);
    met += meets;
    if (sampled) EXPECT_TRUE(meets) << i;
    if (meets) EXPECT_TRUE(near) << i;
  }
  EXPECT_GT(met, 100);
  EXPECT_LT(met, 1900);
}

}  // namespace
}  // namespace densemap
