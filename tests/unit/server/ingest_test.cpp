#include "densemap/server/ingest.hpp"
#include "densemap/query/version_delta.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <map>
#include <mutex>
#include <thread>

#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/test_support/failing_allocations.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap::server {
namespace {

using namespace std::chrono_literals;

RawScan rawScan(std::uint64_t seq, int n = 3000) {
  const Point3f origin(0.1F * static_cast<float>(seq), 0.05F, 0.3F);
  const PointCloud cloud = test::adversarialScan(0.2, Point3f::Zero(), n, 6.0, 1000 + seq);
  RawScan raw;
  raw.seq = seq;
  raw.t_world_sensor = {origin.x(), origin.y(), origin.z()};
  for (const auto& p : cloud) raw.xyz.insert(raw.xyz.end(), {p.x(), p.y(), p.z()});
  return raw;
}

bool waitFor(const std::function<bool()>& condition) {
  for (int i = 0; i < 500; ++i) {
    if (condition()) return true;
    std::this_thread::sleep_for(10ms);
  }
  return false;
}

/// Every result and view a pipeline publishes, in order (read them after stop()).
struct Published : std::vector<std::pair<IntegrationResult, std::shared_ptr<const MapView>>> {
  explicit Published(Ingest& pipeline) {
    pipeline.setPublisher(
        [this](const IntegrationResult& r, const std::shared_ptr<const MapView>& v) {
          std::lock_guard lock(mutex);
          emplace_back(r, v);
        });
  }
  std::mutex mutex;
};

/// The map a plain offline integration of the same scans builds.
std::unique_ptr<GridMap> offlineMap(const std::vector<RawScan>& raws, double max_range) {
  auto map = std::make_unique<GridMap>(0.2, SensorModel{});
  Integrator integrator({.max_range_m = max_range});
  for (const RawScan& raw : raws) {
    const Scan scan = *validateScan(raw, ScanLimits{});
    integrator.integrate(*map, scan.pointsWorld(), scan.originWorld());
  }
  return map;
}

/// Submits scans 1..n one at a time, each integrated before the next; returns them.
std::vector<RawScan> feedScans(Ingest& pipeline, std::uint64_t n) {
  std::vector<RawScan> raws;
  for (std::uint64_t seq = 1; seq <= n; ++seq) {
    raws.push_back(rawScan(seq));
    pipeline.submit(raws.back());
    EXPECT_TRUE(waitFor([&] { return pipeline.counters().integrated == seq; })) << "scan " << seq;
  }
  return raws;
}

/// The cells of the offline map of `raws` whose value `view` does not hold.
std::size_t mismatchesWithOffline(const MapView& view, const std::vector<RawScan>& raws,
                                  double max_range) {
  std::size_t mismatches = 0;
  offlineMap(raws, max_range)->forEachKnown([&](const VoxelKey& k, float v) {
    mismatches += view.logOdds(k) != v;
  });
  return mismatches;
}

TEST(Pipeline, PublishedViewEqualsTheOfflineMapAndDeltasReproduceEachVersion) {
  IngestOptions options{
      .engine = {.resolution_m = 0.2, .max_range_m = 5.0}, .threads = 2, .queue_depth = 8};
  options.engine.collect_changes = true;
  auto sut = Ingest::create(options);
  ASSERT_TRUE(sut);
  Published published(**sut);
  (*sut)->start();
  const std::vector<RawScan> raws = feedScans(**sut, 5);
  (*sut)->stop();
  const auto offline = offlineMap(raws, 5.0);
  const auto view = (*sut)->view();
  EXPECT_EQ(view->version(), 5U);
  EXPECT_EQ(view->knownCells(), offline->knownCells());
  EXPECT_EQ(mismatchesWithOffline(*view, raws, 5.0), 0U);

  ASSERT_EQ(published.size(), 5U);
  auto previous = MapView::fromMap(GridMap(0.2, SensorModel{}), 0);
  GridMap rebuilt(0.2, SensorModel{});
  for (const auto& [result, next] : published) {
    EXPECT_EQ(result.base_version, previous->version());
    // Both encodings of a version's changes reproduce it: the cell list and the diff of the
    // written blocks (what map/delta carries).
    rebuilt.applyChanges(result.changes);
    const auto diffed = diffVersions(*previous, *next, result.written_blocks).changes();
    EXPECT_EQ(diffed.size(), result.changes.size());
    std::size_t diff = 0;
    next->forEachKnown([&](const VoxelKey& k, float v) { diff += rebuilt.logOdds(k) != v; });
    EXPECT_EQ(diff, 0U);
    EXPECT_EQ(rebuilt.knownCells(), next->knownCells());
    previous = next;
  }
  // Old views are immutable: each held version still equals the offline map after its scans
  // (the views read the one, since-changed map's store at their version).
  EXPECT_LT(published.front().second->knownCells(), view->knownCells());
  for (std::size_t k = 0; k < published.size(); ++k) {
    const auto expected = offlineMap({raws.begin(), raws.begin() + k + 1}, 5.0);
    const auto& held = *published[k].second;
    EXPECT_EQ(held.knownCells(), expected->knownCells()) << "version " << k + 1;
    std::size_t wrong = 0;
    expected->forEachKnown([&](const VoxelKey& key, float v) { wrong += held.logOdds(key) != v; });
    EXPECT_EQ(wrong, 0U) << "version " << k + 1;
  }
}

TEST(Pipeline, WarmUpLeavesTheMapEmptyAndTheScansMapUnchangedOnBothBackends) {
  // The warm-up's fan goes into a scratch map (MapKind::warmUp): the served map starts empty at
  // version 0 and ends as the offline map of the scans, cell for cell.
  for (const Backend backend : {Backend::kGrid, Backend::kOctree}) {
    IngestOptions options{.engine = {.backend = backend, .resolution_m = 0.2, .max_range_m = 5.0},
                          .threads = 2};
    options.engine.warm_up = true;
    auto sut = Ingest::create(options);
    ASSERT_TRUE(sut);
    EXPECT_EQ((*sut)->view()->knownCells(), 0U);
    EXPECT_EQ((*sut)->view()->version(), 0U);
    (*sut)->start();
    const std::vector<RawScan> raws = feedScans(**sut, 3);
    (*sut)->stop();
    const auto view = (*sut)->view();
    EXPECT_EQ(view->knownCells(), offlineMap(raws, 5.0)->knownCells());
    EXPECT_EQ(mismatchesWithOffline(*view, raws, 5.0), 0U) << backendName(backend);
  }
}

TEST(Pipeline, AKeepRadiusEvictsExactlyWhatTheOfflineMapLosesAndDeltasFollow) {
  // keep_radius_m 3: after each scan, blocks whose centre is more than 3 m from its origin go.
  IngestOptions options{
      .engine = {.resolution_m = 0.2, .max_range_m = 5.0}, .threads = 2, .queue_depth = 8};
  options.engine.keep_radius_m = 3.0;
  options.engine.collect_changes = true;
  auto sut = Ingest::create(options);
  ASSERT_TRUE(sut);
  Published published(**sut);
  (*sut)->start();
  // The plain path: integrate offline, then drop the same blocks.
  GridMap offline(0.2, SensorModel{});
  Integrator integrator({.max_range_m = 5.0});
  std::size_t evicted = 0;
  for (std::uint64_t seq = 1; seq <= 8; ++seq) {
    RawScan raw = rawScan(seq);
    raw.t_world_sensor = {2.5F * static_cast<float>(seq), 0.05F, 0.3F};  // 2.5 m per scan
    (*sut)->submit(raw);
    ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == seq; }));
    const Scan scan = *validateScan(raw, ScanLimits{});
    integrator.integrate(offline, scan.pointsWorld(), scan.originWorld());
    const Point3f origin = scan.originWorld();
    evicted +=
        offline.evictBlocks([&](const Point3f& c) { return (c - origin).norm() <= 3.0F; }).cells;
  }
  (*sut)->stop();
  const auto view = (*sut)->view();
  EXPECT_EQ(view->knownCells(), offline.knownCells());
  std::size_t mismatches = 0;
  offline.forEachKnown([&](const VoxelKey& k, float v) { mismatches += view->logOdds(k) != v; });
  EXPECT_EQ(mismatches, 0U);
  EXPECT_GT(evicted, 1000U);
  EXPECT_EQ((*sut)->counters().evicted_cells, evicted);
  // Every version's change list and written-block diff reproduce it, evictions included (a
  // cell a scan changed and the eviction then dropped is in the list twice, in the diff once).
  ASSERT_EQ(published.size(), 8U);
  auto previous = MapView::fromMap(GridMap(0.2, SensorModel{}), 0);
  GridMap from_changes(0.2, SensorModel{}), from_diffs(0.2, SensorModel{});
  for (const auto& [result, next] : published) {
    from_changes.applyChanges(result.changes);
    from_diffs.applyChanges(diffVersions(*previous, *next, result.written_blocks).changes());
    for (const GridMap* rebuilt : {&from_changes, &from_diffs}) {
      std::size_t diff = 0;
      next->forEachKnown([&](const VoxelKey& k, float v) { diff += rebuilt->logOdds(k) != v; });
      EXPECT_EQ(diff, 0U) << "version " << next->version();
      EXPECT_EQ(rebuilt->knownCells(), next->knownCells()) << "version " << next->version();
    }
    previous = next;
  }
  // Eviction needs the grid backend and the log-odds map.
  IngestOptions octree = options;
  octree.engine.backend = Backend::kOctree;
  EXPECT_FALSE(Ingest::create(octree));
}

TEST(Pipeline, FallingBehindDropsOldScansNeverQueuesThem) {
  auto sut = Ingest::create({.engine = {.resolution_m = 0.05}, .threads = 1, .queue_depth = 2});
  ASSERT_TRUE(sut);
  (*sut)->start();
  for (std::uint64_t seq = 1; seq <= 40; ++seq) (*sut)->submit(rawScan(seq, 20000));
  ASSERT_TRUE(waitFor([&] {
    const auto c = (*sut)->counters();
    return c.integrated + c.dropped == 40;
  }));
  (*sut)->stop();
  const auto c = (*sut)->counters();
  EXPECT_EQ(c.received, 40U);
  EXPECT_GT(c.dropped, 0U);
  EXPECT_EQ(c.integrated + c.dropped, 40U);
  EXPECT_EQ((*sut)->view()->version(), c.integrated);
}

TEST(Pipeline, BadScansAreRejectedWithTheirReasonAndLeaveTheMapUnchanged) {
  auto sut = Ingest::create(
      {.engine = {.resolution_m = 0.2, .limits = {.max_points = 5000, .max_abs_position_m = 100.0}},
       .threads = 2,
       .queue_depth = 16});
  ASSERT_TRUE(sut);
  std::vector<RejectReason> reasons;
  std::mutex m;
  (*sut)->setRejectHandler([&](const RawScan&, const Rejection& r) {
    std::lock_guard lock(m);
    reasons.push_back(r.reason);
  });
  (*sut)->start();
  (*sut)->submit(rawScan(1));
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 1; }));
  const auto before = (*sut)->view();

  std::vector<RawScan> bad(7, rawScan(2));
  bad[0].xyz[4] = std::numeric_limits<float>::quiet_NaN();
  bad[1].xyz[7] = std::numeric_limits<float>::infinity();
  bad[2].xyz.pop_back();
  bad[3] = rawScan(2, 6000);  // over max_points
  bad[4].q_world_sensor = {0.5, 0.0, 0.0, 0.0};
  bad[5].t_world_sensor[1] = 1e6;
  bad[6].xyz.clear();
  RawScan nan_q = rawScan(2);
  nan_q.q_world_sensor[2] = std::nan("");
  bad.push_back(nan_q);
  for (auto& b : bad) (*sut)->submit(b);
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().rejected == bad.size(); }));
  (*sut)->stop();
  const auto c = (*sut)->counters();
  EXPECT_EQ(c.integrated, 1U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kNonFinitePoint)], 2U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kLengthNotMultipleOf3)], 1U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kTooManyPoints)], 1U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kBadQuaternion)], 2U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kPoseOutOfBounds)], 1U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kEmpty)], 1U);
  EXPECT_FALSE(c.last_reject_reason.empty());
  EXPECT_EQ((*sut)->view(), before);  // nothing was published
}

TEST(Pipeline, AnEngineThatThrowsRejectsTheScanAndTheWorkerGoesOn) {
  auto sut = Ingest::create({.engine = {.resolution_m = 0.2}, .threads = 2, .queue_depth = 16});
  ASSERT_TRUE(sut);
  std::atomic<int> announced{0};
  std::atomic<bool> throw_from_publisher{false};
  (*sut)->setPublisher([&](const IntegrationResult&, const std::shared_ptr<const MapView>&) {
    ++announced;
    if (throw_from_publisher) throw std::runtime_error("publisher failed");
  });
  (*sut)->start();
  (*sut)->submit(rawScan(1));
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 1; }));
  const auto before = (*sut)->view();

  // Out of memory inside the engine: the scan's first large allocation (its points) throws
  // on the worker. The scan is rejected as internal and nothing is published.
  RawScan big = rawScan(2, 20000);
  {
    test::FailingAllocations failing(64 << 10, 1);
    (*sut)->submit(std::move(big));
    ASSERT_TRUE(waitFor([&] { return (*sut)->counters().rejected == 1; }));
    EXPECT_EQ(failing.failed(), 1U);
  }
  EXPECT_EQ((*sut)->view(), before);
  auto c = (*sut)->counters();
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kInternal)], 1U);
  EXPECT_NE(c.last_reject_reason.find("integration failed"), std::string::npos)
      << c.last_reject_reason;

  // A command that throws answers with an error; the next one runs.
  auto failed = (*sut)->command([](OccupancyMap&, CellChanges&) -> Expected<std::string> {
    throw std::runtime_error("boom");
  });
  ASSERT_EQ(failed.wait_for(5s), std::future_status::ready);
  const auto failed_reply = failed.get();
  ASSERT_FALSE(failed_reply);
  EXPECT_NE(failed_reply.error().message.find("boom"), std::string::npos);
  auto fine = (*sut)->command(
      [](OccupancyMap&, CellChanges&) -> Expected<std::string> { return std::string("ok"); });
  ASSERT_EQ(fine.wait_for(5s), std::future_status::ready);
  EXPECT_EQ(fine.get().value_or(""), "ok");

  // A publisher that throws loses its announcement, not the scan.
  throw_from_publisher = true;
  (*sut)->submit(rawScan(3));
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 2; }));
  throw_from_publisher = false;
  (*sut)->submit(rawScan(4));
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 3; }));
  (*sut)->stop();
  c = (*sut)->counters();
  EXPECT_EQ(c.rejected, 1U);
  EXPECT_EQ(announced.load(), 3);
  EXPECT_EQ((*sut)->view()->version(), 3U);
}

TEST(Pipeline, CommandsRunBetweenScansAndPublishTheirChanges) {
  auto sut = Ingest::create({.engine = {.resolution_m = 0.2}, .threads = 2});
  ASSERT_TRUE(sut);
  (*sut)->start();
  (*sut)->submit(rawScan(1));
  ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 1; }));
  const std::size_t known = (*sut)->view()->knownCells();
  auto cleared =
      (*sut)->command([](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
        const VoxelKey lo = *map.grid().pointToKey(Point3f(-1, -1, -1));
        const VoxelKey hi = *map.grid().pointToKey(Point3f(1, 1, 1));
        return std::to_string(map.clearBox(lo, hi, &changes));
      });
  ASSERT_EQ(cleared.wait_for(5s), std::future_status::ready);
  const auto erased = cleared.get();
  ASSERT_TRUE(erased);
  EXPECT_GT(std::stoul(*erased), 0U);
  EXPECT_EQ((*sut)->view()->knownCells(), known - std::stoul(*erased));
  EXPECT_FALSE(
      (*sut)->view()->logOdds(*(*sut)->view()->grid().pointToKey(Point3f(0.1F, 0.1F, 0.1F))));
  (*sut)->stop();
  // After stop, commands still run (the server's shutdown snapshot depends on it).
  auto after = (*sut)->command([](OccupancyMap& map, CellChanges&) -> Expected<std::string> {
    return std::to_string(map.knownCells());
  });
  EXPECT_EQ(after.wait_for(1s), std::future_status::ready);
}

// A kernel map evicts with the published grid: the pipeline's map equals an offline
// kernel map that evicts the same blocks after each scan (keep radius around each scan's origin).
TEST(Pipeline, KernelMapEvictionEqualsTheOfflineMapMinusTheEvictedBlocks) {
  const auto method = kernel::KernelMethod::kAkimapRays;
  constexpr double kRadius = 3.0;
  auto sut = Ingest::create({.engine = {.resolution_m = 0.2,
                                        .max_range_m = 5.0,
                                        .kernel = method,
                                        .keep_radius_m = kRadius},
                             .threads = 2});
  ASSERT_TRUE(sut) << sut.error().message;
  (*sut)->start();
  std::vector<RawScan> raws = {rawScan(1, 1500), rawScan(30, 1500)};  // origins 3 m apart
  for (std::uint64_t i = 0; i < raws.size(); ++i) {
    (*sut)->submit(raws[i]);
    ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == i + 1; }));
  }
  auto options = kernel::KernelOptions::defaults(method);
  options.max_range = 5.0;
  kernel::KernelMap offline(0.2, options), unbounded(0.2, options);
  for (const RawScan& raw : raws) {
    const Scan scan = *validateScan(raw, ScanLimits{});
    offline.integrate(scan.pointsWorld(), scan.originWorld());
    unbounded.integrate(scan.pointsWorld(), scan.originWorld());
    const Point3f origin = scan.originWorld();
    offline.evictBlocks([&](const Point3f& centre) {
      return (centre - origin).cast<double>().squaredNorm() <= kRadius * kRadius;
    });
  }
  const auto view = (*sut)->view();
  EXPECT_LT(offline.knownCells(), unbounded.knownCells());  // something was evicted
  ASSERT_EQ(view->knownCells(), offline.knownCells());
  std::size_t mismatches = 0;
  offline.forEachKnown([&](const VoxelKey& k, double p) {
    const auto l = view->logOdds(k);
    mismatches += !l || *l != static_cast<float>(std::log(p / (1.0 - p)));
  });
  EXPECT_EQ(mismatches, 0U);
  EXPECT_GT((*sut)->counters().evicted_blocks, 0U);
  // The evidence itself went with the grid's blocks (not only the published cells): the same
  // cells with the same alpha and beta as the offline map's.
  const auto saved = (*sut)->savedState();
  ASSERT_TRUE(saved.kernel.has_value());
  const kernel::KernelEvidence expected = offline.evidence();
  std::map<std::uint64_t, std::pair<double, double>> wanted, held;
  for (std::size_t i = 0; i < expected.keys.size(); ++i) {
    wanted[expected.keys[i].packed()] = {expected.alpha[i], expected.beta[i]};
  }
  for (std::size_t i = 0; i < saved.kernel->keys.size(); ++i) {
    held[saved.kernel->keys[i].packed()] = {saved.kernel->alpha[i], saved.kernel->beta[i]};
  }
  EXPECT_EQ(held.size(), wanted.size());
  EXPECT_TRUE(held == wanted);
  (*sut)->stop();
}

TEST(Pipeline, KernelMapKindsPublishLogitOfTheOfflineKernelMapAndClearBothStores) {
  for (const auto method : {kernel::KernelMethod::kAkimap, kernel::KernelMethod::kBgk,
                            kernel::KernelMethod::kBgkl, kernel::KernelMethod::kAkimapRays}) {
    const std::string name(kernel::kernelMethodName(method));
    auto sut = Ingest::create(
        {.engine = {.resolution_m = 0.2, .max_range_m = 5.0, .kernel = method}, .threads = 2});
    ASSERT_TRUE(sut) << name;
    (*sut)->start();
    std::vector<RawScan> raws = {rawScan(1, 1500), rawScan(2, 1500)};
    for (std::uint64_t i = 0; i < raws.size(); ++i) {
      (*sut)->submit(raws[i]);
      ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == i + 1; })) << name;
    }
    auto options = kernel::KernelOptions::defaults(method);
    options.max_range = 5.0;
    kernel::KernelMap offline(0.2, options);
    for (const RawScan& raw : raws) {
      const Scan scan = *validateScan(raw, ScanLimits{});
      offline.integrate(scan.pointsWorld(), scan.originWorld());
    }
    const auto view = (*sut)->view();
    ASSERT_EQ(view->knownCells(), offline.knownCells()) << name;
    std::size_t mismatches = 0, occupied = 0;
    offline.forEachKnown([&](const VoxelKey& k, double p) {
      const auto l = view->logOdds(k);
      mismatches += !l || *l != static_cast<float>(std::log(p / (1.0 - p)));
      occupied += p > 0.5;
    });
    EXPECT_EQ(mismatches, 0U) << name;
    EXPECT_GT(occupied, 0U) << name;
    EXPECT_LT(occupied, offline.knownCells()) << name;

    // Clearing a box forgets the kernel evidence too: the next scan's values there come from
    // that scan alone.
    auto cleared =
        (*sut)->command([](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
          return std::to_string(map.clearBox({0, 0, 0}, {65535, 65535, 65535}, &changes));
        });
    ASSERT_EQ(cleared.wait_for(5s), std::future_status::ready);
    ASSERT_TRUE(cleared.get());
    EXPECT_EQ((*sut)->view()->knownCells(), 0U) << name;
    (*sut)->submit(raws[1]);
    ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 3; })) << name;
    (*sut)->stop();
    kernel::KernelMap fresh(0.2, options);
    const Scan scan = *validateScan(raws[1], ScanLimits{});
    fresh.integrate(scan.pointsWorld(), scan.originWorld());
    if (method == kernel::KernelMethod::kAkimap || method == kernel::KernelMethod::kAkimapRays) {
      // AKIMap's random free samples (which shape akimap_rays' occupied kernels too) depend on
      // the scan count: same coverage up to a few cells (the map before clearing covered far
      // more).
      EXPECT_NEAR(static_cast<double>((*sut)->view()->knownCells()),
                  static_cast<double>(fresh.knownCells()), 0.01 * fresh.knownCells());
    } else {
      EXPECT_EQ((*sut)->view()->knownCells(), fresh.knownCells()) << name;
    }
  }
}

TEST(Pipeline, UpsampleStageIntegratesTheDensifiedScan) {
  for (const char* method : {"bilinear", "iln"}) {
    SCOPED_TRACE(method);
    const auto up = upsample::makeUpsampleOptions(method, {.rows = 16, .cols = 256},
                                                  {.rows = 61, .cols = 512}, DENSEMAP_ILN_MODEL);
    ASSERT_TRUE(up) << up.error().message;
    auto sut = Ingest::create(
        {.engine = {.resolution_m = 0.2, .max_range_m = 20.0, .upsample = *up}, .threads = 2});
    ASSERT_TRUE(sut);
    // A 16-beam scan: a sphere of 4 m around the sensor in one sector, 6 m elsewhere.
    RawScan raw;
    raw.seq = 1;
    upsample::RangeImage image(up->input);
    for (int r = 0; r < image.layout.rows; ++r) {
      for (int c = 0; c < image.layout.cols; ++c) image.at(r, c) = c < 64 ? 4.0F : 6.0F;
    }
    for (const Point3f& p : upsample::backProject(image)) {
      raw.xyz.insert(raw.xyz.end(), {p.x(), p.y(), p.z()});
    }
    (*sut)->start();
    (*sut)->submit(raw);
    ASSERT_TRUE(waitFor([&] { return (*sut)->counters().integrated == 1; }));
    (*sut)->stop();
    GridMap expected(0.2, SensorModel{}), sparse(0.2, SensorModel{});
    Integrator integrator({.max_range_m = 20.0});
    const Scan scan = *validateScan(raw, ScanLimits{});
    integrator.integrate(expected, upsample::upsamplePoints(scan.points, *up), scan.originWorld());
    integrator.integrate(sparse, scan.points, scan.originWorld());
    const auto view = (*sut)->view();
    EXPECT_EQ(view->knownCells(), expected.knownCells());
    std::size_t mismatches = 0;
    expected.forEachKnown([&](const VoxelKey& k, float v) { mismatches += view->logOdds(k) != v; });
    EXPECT_EQ(mismatches, 0U);
    EXPECT_GT(expected.knownCells(), sparse.knownCells()) << "densified scans fill more cells";
  }
}

TEST(Pipeline, RejectsAnUpsampleStageWithMismatchedFieldsOfView) {
  upsample::UpsampleOptions up;
  up.output.top_deg = 20.0;
  EXPECT_FALSE(Ingest::create({.engine = {.upsample = up}}));
}

TEST(LatestWinsQueue, DropsTheOldestWhenFullAndCountsIt) {
  LatestWinsQueue<int> sut(2);
  std::vector<int> dropped;
  sut.push(1, &dropped);
  sut.push(2, &dropped);
  EXPECT_TRUE(dropped.empty());
  sut.push(3, &dropped);
  EXPECT_EQ(dropped, std::vector<int>{1});  // handed back, so the caller knows whose it was
  EXPECT_EQ(sut.dropped(), 1U);
  EXPECT_EQ(sut.pop(0ms), 2);
  EXPECT_EQ(sut.pop(0ms), 3);
  EXPECT_FALSE(sut.pop(1ms).has_value());
  sut.push(4);
  const auto discarded = sut.close();
  ASSERT_EQ(discarded.size(), 1U);
  EXPECT_EQ(discarded.front(), 4);
  EXPECT_EQ(sut.dropped(), 2U);
  EXPECT_FALSE(sut.push(5));
}

TEST(LatestWinsQueue, PerKeyTheLatestWinsWithinItsOwnKeyAndTheTotalIsBounded) {
  // Items "a1", "b1", ... are keyed by their letter.
  const std::map<std::string, std::string> letter = {
      {"a1", "a"}, {"a2", "a"}, {"a3", "a"}, {"b1", "b"}, {"b2", "b"}, {"c1", "c"}, {"d1", "d"}};
  LatestWinsQueue<std::string> sut(
      2, 5, [&](const std::string& s) -> const std::string& { return letter.at(s); });
  std::vector<std::string> dropped;
  for (const char* item : {"a1", "b1", "a2", "b2"}) sut.push(item, &dropped);
  EXPECT_TRUE(dropped.empty());
  sut.push("a3", &dropped);  // a is full: its oldest goes, b keeps both
  EXPECT_EQ(dropped, std::vector<std::string>{"a1"});
  dropped.clear();
  sut.push("c1", &dropped);  // 5 in all: fits
  EXPECT_TRUE(dropped.empty());
  sut.push("d1", &dropped);  // beyond the total: the oldest of any key goes
  EXPECT_EQ(dropped, std::vector<std::string>{"b1"});
  EXPECT_EQ(sut.dropped(), 2U);
  for (const char* expected : {"a2", "b2", "a3", "c1", "d1"}) EXPECT_EQ(sut.pop(0ms), expected);
}

// A backlog (clouds a late transform released) goes in only where it pushes
// nothing out: hasRoomFor says so exactly when push would drop nothing.
TEST(LatestWinsQueue, HasRoomForExactlyWhenAPushWouldDropNothing) {
  const std::map<std::string, std::string> letter = {{"a1", "a"}, {"a2", "a"}, {"a3", "a"},
                                                     {"b1", "b"}, {"b2", "b"}, {"c1", "c"}};
  LatestWinsQueue<std::string> sut(
      2, 4, [&](const std::string& s) -> const std::string& { return letter.at(s); });
  for (const char* item : {"a1", "a2", "b1"}) {
    EXPECT_TRUE(sut.hasRoomFor(item));
    sut.push(item);
  }
  EXPECT_FALSE(sut.hasRoomFor("a3"));  // a holds 2
  EXPECT_TRUE(sut.hasRoomFor("b2"));
  sut.push("b2");
  EXPECT_FALSE(sut.hasRoomFor("c1"));  // 4 in all
  std::vector<std::string> dropped;
  sut.push("c1", &dropped);
  EXPECT_EQ(dropped.size(), 1U);  // as predicted
  EXPECT_EQ(sut.pop(0ms), "a2");
  EXPECT_TRUE(sut.hasRoomFor("a3"));
}

TEST(LatestWinsQueue, ManySensorsWithAScanEachLoseNoneAndTheFullestSensorGivesWay) {
  // 24 sensors with one scan each against a total of 16 (8 x depth 2) lost
  // 7 scans to the total cap. Items are "KEY:N"; the key is before the colon.
  std::vector<std::string> keys;
  LatestWinsQueue<std::string> sut(
      2, 16,
      [&keys](const std::string& s) -> const std::string& {
        const std::string key = s.substr(0, s.find(':'));
        for (const std::string& k : keys)
          if (k == key) return k;
        throw std::logic_error("unknown key " + key);
      },
      /*max_keys=*/30);
  for (int i = 0; i < 40; ++i) keys.push_back("s" + std::to_string(i));
  std::vector<std::string> dropped;
  for (int i = 0; i < 24; ++i) sut.push("s" + std::to_string(i) + ":1", &dropped);
  EXPECT_TRUE(dropped.empty());
  EXPECT_EQ(sut.size(), 24U);
  sut.push("s0:2", &dropped);  // s0 may hold 2: fits (every other sensor holds 1)
  EXPECT_TRUE(dropped.empty());
  sut.push("s1:2", &dropped);  // beyond the total: the fullest sensor (s0) gives its oldest
  EXPECT_EQ(dropped, std::vector<std::string>{"s0:1"});
  dropped.clear();
  // Beyond max_keys sensors at once, a sensor's only scan goes: the oldest of all.
  for (int i = 24; i < 30; ++i) sut.push("s" + std::to_string(i) + ":1", &dropped);
  EXPECT_EQ(dropped, std::vector<std::string>{"s1:1"});  // s1 held two: it gave way first
  dropped.clear();
  sut.push("s30:1", &dropped);  // 31 keys > 30, every key holds one: the oldest of all goes
  EXPECT_EQ(dropped, std::vector<std::string>{"s2:1"});
  EXPECT_EQ(sut.dropped(), 3U);
}

// One scan per sensor always fitting let 64 sensor ids hold
// 65 scans (1.5 GB at 2M points each); waiting scans now also share a byte budget: beyond it
// the sensor with the most waiting gives up its oldest, else the oldest scan goes, and the
// bytes waiting never exceed the budget (one item larger than all of it waits alone).
TEST(LatestWinsQueue, WaitingItemsStayWithinTheByteBudgetTheFullestKeyGivingWayFirst) {
  // Items "KEY:BYTES".
  const auto key_of = [](const std::string& s) -> const std::string& {
    static thread_local std::string key;
    key = s.substr(0, s.find(':'));
    return key;
  };
  const auto bytes_of = [](const std::string& s) -> std::size_t {
    return std::stoul(s.substr(s.find(':') + 1));
  };
  LatestWinsQueue<std::string> sut(4, 64, key_of, 64, bytes_of, 100);
  std::vector<std::string> dropped;
  for (const char* item : {"a:30", "b:20", "a:30"}) sut.push(item, &dropped);
  EXPECT_TRUE(dropped.empty());
  EXPECT_EQ(sut.bytes(), 80U);
  sut.push("c:30", &dropped);  // 110 > 100: a (two waiting) gives its oldest
  EXPECT_EQ(dropped, std::vector<std::string>{"a:30"});
  EXPECT_EQ(sut.bytes(), 80U);
  dropped.clear();
  sut.push("d:60", &dropped);  // one each: the oldest of all go until it fits (b, then a)
  EXPECT_EQ(dropped, (std::vector<std::string>{"b:20", "a:30"}));
  EXPECT_EQ(sut.bytes(), 90U);
  dropped.clear();
  sut.push("e:500", &dropped);  // larger than the budget: waits alone
  EXPECT_EQ(dropped, (std::vector<std::string>{"c:30", "d:60"}));
  EXPECT_EQ(sut.bytes(), 500U);
  EXPECT_EQ(sut.pop(0ms), "e:500");
  EXPECT_EQ(sut.bytes(), 0U);
  EXPECT_EQ(sut.dropped(), 5U);
}

TEST(SensorTally, CountsGapsWithinEachSensorsIncreasingSequence) {
  SensorTally sut;
  for (std::uint64_t seq : {1, 2, 5, 6, 10}) sut.received("a", seq);  // 2 + 3 skipped
  for (std::uint64_t seq : {7, 8, 1, 2}) sut.received("b", seq);      // a restart, no gap
  sut.integrated("a", 5.0);
  sut.dropped("b");
  sut.rejected("b");
  const auto sensors = sut.sensors();
  ASSERT_EQ(sensors.size(), 2U);
  EXPECT_EQ(sensors[0].sensor_id, "a");
  EXPECT_EQ(sensors[0].received, 5U);
  EXPECT_EQ(sensors[0].seq_gaps, 5U);
  EXPECT_EQ(sensors[0].integrated, 1U);
  EXPECT_EQ(sensors[1].seq_gaps, 0U);
  EXPECT_EQ(sensors[1].dropped, 1U);
  EXPECT_EQ(sensors[1].rejected, 1U);
}

TEST(SensorTally, EachSensorsLatencyPercentilesAreOverItsOwnLastScans) {
  SensorTally sut;
  // "a": 1 .. 100 ms, then 300 more at 1000 ms push all but 1000 ms out of its window.
  for (int i = 1; i <= 100; ++i) sut.integrated("a", i);
  sut.integrated("b", 7.0);
  auto sensors = sut.sensors();
  ASSERT_EQ(sensors.size(), 2U);
  EXPECT_EQ(sensors[0].latency_p50_ms, 50.0);
  EXPECT_EQ(sensors[0].latency_p99_ms, 99.0);
  EXPECT_EQ(sensors[1].latency_p50_ms, 7.0);
  EXPECT_EQ(sensors[1].latency_p99_ms, 7.0);
  for (int i = 0; i < 300; ++i) sut.integrated("a", 1000.0);
  sensors = sut.sensors();
  EXPECT_EQ(sensors[0].integrated, 400U);
  EXPECT_EQ(sensors[0].latency_p50_ms, 1000.0);
  EXPECT_EQ(sensors[1].latency_p50_ms, 7.0);
}

TEST(SensorTally, KeepsAtMostSixtyFourIdsApartAndCountsTheRestTogether) {
  SensorTally sut;
  for (int i = 0; i < 100; ++i) sut.received("robot" + std::to_string(i), 1);
  const auto sensors = sut.sensors();
  EXPECT_LE(sensors.size(), SensorTally::kMaxSensors + 1);
  std::uint64_t total = 0;
  for (const auto& c : sensors) total += c.received;
  EXPECT_EQ(total, 100U);
  EXPECT_TRUE(std::any_of(sensors.begin(), sensors.end(), [](const SensorCounters& c) {
    return c.sensor_id == SensorTally::kOtherSensors && c.received == 36;
  }));
}

TEST(Pipeline, ASensorIdBeyondTheBoundIsACountedRejectionNeitherKeptNorEchoed) {
  auto sut = Ingest::create({.engine = {.resolution_m = 0.2}, .threads = 1, .queue_depth = 2});
  ASSERT_TRUE(sut);
  std::vector<std::string> rejected_ids;
  (*sut)->setRejectHandler(
      [&](const RawScan& raw, const Rejection&) { rejected_ids.push_back(raw.sensor_id); });
  (*sut)->start();
  RawScan huge = rawScan(1, 1000);
  huge.sensor_id = std::string(1'000'000, 'x');
  (*sut)->submit(std::move(huge));
  RawScan bound = rawScan(2, 1000);
  bound.sensor_id = std::string(kMaxSensorIdBytes, 'y');
  (*sut)->submit(std::move(bound));
  ASSERT_TRUE(waitFor([&] {
    const auto c = (*sut)->counters();
    return c.integrated + c.rejected == 2;
  }));
  (*sut)->stop();
  const auto c = (*sut)->counters();
  EXPECT_EQ(c.received, 2U);
  EXPECT_EQ(c.integrated, 1U);
  EXPECT_EQ(c.rejected_by_reason[static_cast<int>(RejectReason::kSensorIdTooLong)], 1U);
  EXPECT_NE(c.last_reject_reason.find("1000000 bytes"), std::string::npos) << c.last_reject_reason;
  ASSERT_EQ(rejected_ids.size(), 1U);
  EXPECT_EQ(rejected_ids[0].size(), kMaxSensorIdBytes);
  std::size_t id_bytes = 0;
  for (const auto& sensor : c.sensors) id_bytes += sensor.sensor_id.size();
  EXPECT_EQ(id_bytes, 2 * kMaxSensorIdBytes);
  // The library path refuses it too.
  RawScan direct = rawScan(3, 10);
  direct.sensor_id = std::string(kMaxSensorIdBytes + 1, 'z');
  const auto refused = validateScan(direct, ScanLimits{});
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().reason, RejectReason::kSensorIdTooLong);
  EXPECT_EQ(rejectReasonName(RejectReason::kSensorIdTooLong), "sensor_id_too_long");
}

TEST(Pipeline, OneSensorsBurstNeverPushesOutAnotherSensorsScan) {
  // The worker is busy with front's first scan while rear's scan waits and front floods the
  // queue: front's own older scans are dropped, rear's is integrated.
  auto sut = Ingest::create({.engine = {.resolution_m = 0.05}, .threads = 1, .queue_depth = 2});
  ASSERT_TRUE(sut);
  (*sut)->start();
  auto scan = [](const char* id, std::uint64_t seq) {
    RawScan r = rawScan(seq, 20000);
    r.sensor_id = id;
    return r;
  };
  (*sut)->submit(scan("front", 1));
  (*sut)->submit(scan("rear", 1));
  for (std::uint64_t seq = 2; seq <= 20; ++seq) (*sut)->submit(scan("front", seq));
  ASSERT_TRUE(waitFor([&] {
    const auto c = (*sut)->counters();
    return c.integrated + c.dropped == 21;
  }));
  (*sut)->stop();
  const auto c = (*sut)->counters();
  ASSERT_EQ(c.sensors.size(), 2U);
  EXPECT_EQ(c.sensors[1].sensor_id, "rear");
  EXPECT_EQ(c.sensors[1].integrated, 1U);
  EXPECT_EQ(c.sensors[1].dropped, 0U);
  EXPECT_GT(c.sensors[0].dropped, 0U);  // front fell behind, at its own expense
}

TEST(Pipeline, CountsEachSensorsScansAndTheirSeqGaps) {
  // One worker thread on a fine map falls behind: scans are dropped. Every scan of each sensor
  // ends integrated, dropped or rejected, and a skipped seq is a gap of that sensor only.
  auto sut = Ingest::create({.engine = {.resolution_m = 0.05}, .threads = 1, .queue_depth = 2});
  ASSERT_TRUE(sut);
  (*sut)->start();
  std::uint64_t sent_a = 0, sent_b = 0;
  for (std::uint64_t seq = 1; seq <= 30; ++seq) {
    RawScan a = rawScan(seq, 5000);
    a.sensor_id = "front";
    (*sut)->submit(std::move(a));
    ++sent_a;
    if (seq % 3 != 0) {  // "rear" skips every third seq
      RawScan b = rawScan(seq, 5000);
      b.sensor_id = "rear";
      if (seq == 20) b.xyz.push_back(1.0F);  // length not a multiple of 3: rejected
      (*sut)->submit(std::move(b));
      ++sent_b;
    }
  }
  (*sut)->stop();
  const auto c = (*sut)->counters();
  ASSERT_EQ(c.sensors.size(), 2U);
  const SensorCounters& front = c.sensors[0];
  const SensorCounters& rear = c.sensors[1];
  EXPECT_EQ(front.sensor_id, "front");
  EXPECT_EQ(front.received, sent_a);
  EXPECT_EQ(front.seq_gaps, 0U);
  EXPECT_EQ(rear.received, sent_b);
  EXPECT_EQ(rear.seq_gaps, 9U);  // seqs 3, 6, ..., 27 (30 is never followed)
  for (const SensorCounters& s : c.sensors) {
    EXPECT_EQ(s.integrated + s.dropped + s.rejected, s.received) << s.sensor_id;
  }
  EXPECT_GT(front.dropped + rear.dropped, 0U);  // it did fall behind
  EXPECT_EQ(front.integrated + rear.integrated, c.integrated);
  EXPECT_EQ(front.rejected + rear.rejected, c.rejected);
}

/// A replica's catch-up (Ingest::catchUp): a peer's map of scans 1..8 replaces this map of
/// scans 6..12 (kept since beginCatchUp), the kept scans after the peer's last are integrated
/// into it, and the result is the map of 1..12 at version 12, published as one version whose
/// changes take a reader of the old version to it. A peer's map that ends before the first kept
/// scan is refused (scans between may be missing) and the scans stay kept.
TEST(Pipeline, ACatchUpTakesThePeersMapAndTheKeptScansItLacks) {
  std::vector<RawScan> raws;
  for (std::uint64_t seq = 1; seq <= 12; ++seq) {
    raws.push_back(rawScan(seq));
    raws.back().sensor_id = "robot";
    raws.back().stamp_ns = static_cast<std::int64_t>(seq) * 1000;
  }
  const auto peerMap = [&](std::size_t scans) {
    auto map = std::make_unique<GridMap>(0.2, SensorModel{});
    offlineMap({raws.begin(), raws.begin() + static_cast<std::ptrdiff_t>(scans)}, -1.0)
        ->forEachKnown([&](const VoxelKey& k, float v) { map->setLogOdds(k, v); });
    return map;
  };
  auto ingest = Ingest::create({.engine = {.resolution_m = 0.2}});
  ASSERT_TRUE(ingest);
  Ingest& replica = **ingest;
  Published published(replica);
  replica.beginCatchUp();
  replica.start();
  for (std::size_t i = 5; i < 12; ++i) {
    replica.submit(raws[i]);
    ASSERT_TRUE(waitFor([&] { return replica.counters().integrated == i - 4; }));
  }
  const auto own = replica.view();
  ASSERT_EQ(own->version(), 7U);

  // The peer's map of 1..3: the kept scans start at 6, so 4 and 5 may be missing.
  auto gap = replica.catchUp(peerMap(3), 9, {{"robot", raws[2].stamp_ns}}).get();
  ASSERT_FALSE(gap);
  EXPECT_TRUE(gap.error().message.starts_with(Ingest::kCatchUpGap)) << gap.error().message;
  EXPECT_EQ(replica.view(), own) << "nothing changed";

  auto done = replica.catchUp(peerMap(8), 8, {{"robot", raws[7].stamp_ns}}).get();
  ASSERT_TRUE(done) << done.error().message;
  const auto caught = replica.view();
  EXPECT_EQ(caught->version(), 12U);
  EXPECT_EQ(mismatchesWithOffline(*caught, raws, -1.0), 0U);
  EXPECT_EQ(caught->knownCells(), offlineMap(raws, -1.0)->knownCells());
  const Ingest::Latest latest = replica.latest();
  EXPECT_EQ(latest.view, caught);
  ASSERT_EQ(latest.last_stamps.size(), 1U);
  EXPECT_EQ(latest.last_stamps[0].second, raws[11].stamp_ns);
  // The one version's changes take the old version's cells to the new ones.
  replica.stop();
  ASSERT_FALSE(published.empty());
  const auto& [result, view] = published.back();
  EXPECT_EQ(result.base_version, 7U);
  EXPECT_EQ(result.new_version, 12U);
  GridMap followed(0.2, SensorModel{});
  own->forEachKnown([&](const VoxelKey& k, float v) { followed.setLogOdds(k, v); });
  followed.applyChanges(result.changes);
  EXPECT_EQ(mismatchesWithOffline(*MapView::fromMap(followed, 12), raws, -1.0), 0U);
  EXPECT_EQ(followed.knownCells(), caught->knownCells());

  // A second catch-up: the scans are no longer kept, and the peer is not ahead.
  EXPECT_FALSE(replica.catchUp(peerMap(8), 8, {}).get());
}

}  // namespace
}  // namespace densemap::server
