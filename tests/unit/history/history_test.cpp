// A map's history (core/history): after a correction of past poses, re-integrating from the
// checkpoint before the earliest corrected scan and patching the live map gives, cell for cell,
// the map built from scratch with the corrected poses; again after a second correction (the
// checkpoints the first re-integration replaced hold the corrected map); corrections past what
// the store keeps are counted, not applied.
#include <gtest/gtest.h>


#include "densemap/history/scan_history.hpp"
#include "densemap/query/version_delta.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/drift.hpp"
#include "densemap/test_support/server_clients.hpp"

namespace densemap {
namespace {

/// `n` simulated VLP-16 scans through the indoor scene, stamped 100 ms apart.
std::vector<RawScan> indoorScans(const std::filesystem::path& dir, int n) {
  auto raws = test::simulatedRawScans(dir, test::smallIndoorDrive(n, 90), "robot");
  for (RawScan& raw : raws) raw.stamp_ns = static_cast<std::int64_t>(raw.seq) * 100'000'000;
  return raws;
}

CorrectedPose poseOf(const RawScan& scan) {
  return {scan.stamp_ns, scan.t_world_sensor, scan.q_world_sensor};
}

/// Cells that differ between two views (known in one only, or another value).
std::size_t differing(const MapView& a, const MapView& b) {
  std::vector<std::uint64_t> blocks;
  a.forEachBlock([&](std::uint64_t k, const VoxelBlock&) { blocks.push_back(k); });
  b.forEachBlock([&](std::uint64_t k, const VoxelBlock&) { blocks.push_back(k); });
  return diffVersions(a, b, blocks).size();
}

std::shared_ptr<const MapView> fromScratch(const PipelineOptions& options,
                                           const std::vector<RawScan>& scans) {
  auto engine = Engine::create(options);
  EXPECT_TRUE(engine);
  for (const RawScan& s : scans) EXPECT_TRUE((*engine)->integrate(s));
  return (*engine)->view();
}

/// Re-integrates `history` after `correction` and patches `live`; returns the cells patched.
std::size_t correctAndPatch(Engine& live, ScanHistory& history, const PoseCorrection& correction,
                            std::size_t expect_corrected) {
  const CorrectionOutcome outcome = history.correct(correction);
  EXPECT_EQ(outcome.corrected, expect_corrected);
  EXPECT_EQ(outcome.unmatched, 0U);
  EXPECT_TRUE(outcome.earliest);
  if (!outcome.earliest) return 0;
  const auto from = history.checkpointBefore(*outcome.earliest);
  EXPECT_TRUE(from);
  if (!from) return 0;
  EXPECT_LE(from->index, *outcome.earliest);
  auto re = Reintegration::create(live.options(), *from);
  EXPECT_TRUE(re) << re.error().message;
  if (!re) return 0;
  EXPECT_TRUE((*re)->advance(history, history.store().end()));
  EXPECT_EQ((*re)->next(), history.store().end());
  std::size_t patched = 0;
  IntegrationResult result;
  auto done = live.command(
      [&](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
        patched = (*re)->patch(map, *live.view(), changes);
        return std::string();
      },
      result);
  EXPECT_TRUE(done);
  history.replaceCheckpoints((*re)->checkpoints());
  return patched;
}

TEST(History, ACorrectionReintegratedFromItsCheckpointGivesTheMapOfTheCorrectedPoses) {
  test::TempDir dir;
  const std::vector<RawScan> truth = indoorScans(dir.path(), 160);
  ASSERT_EQ(truth.size(), 160U);
  std::vector<RawScan> live_scans = truth;  // the last 100 drift
  for (std::size_t i = 60; i < truth.size(); ++i) {
    live_scans[i] = test::drifted(truth[i], static_cast<int>(i) - 59, 0.003);
  }
  PipelineOptions options;
  auto live = Engine::create(options);
  ASSERT_TRUE(live);
  auto history = ScanHistory::create(
      {.store = {.directory = dir.path() / "store"}, .checkpoint_every = 25, .max_checkpoints = 16},
      (*live)->view());
  ASSERT_TRUE(history) << history.error().message;
  for (const RawScan& s : live_scans) {
    ASSERT_TRUE((*live)->integrate(s));
    ASSERT_TRUE((*history)->record(s, (*live)->view()));
  }
  EXPECT_EQ((*history)->checkpoints(), 7U);  // at 0, 25, ... 150

  const auto corrected_map = fromScratch(options, truth);
  const std::size_t before = differing(*(*live)->view(), *corrected_map);
  EXPECT_GT(before, 10000U) << "the drift must show in the map for the check to mean anything";

  PoseCorrection correction{.sensor_id = "robot"};
  for (std::size_t i = 60; i < truth.size(); ++i) correction.poses.push_back(poseOf(truth[i]));
  ASSERT_TRUE(checkCorrection(correction, {}));
  const std::size_t patched = correctAndPatch(**live, **history, correction, 100);
  EXPECT_EQ(differing(*(*live)->view(), *corrected_map), 0U);
  EXPECT_EQ(patched, before);

  // A second correction reaches back into the re-integrated part: from the checkpoint the
  // first one replaced, it must give the map of all poses now stored.
  std::vector<RawScan> second = truth;
  PoseCorrection back{.sensor_id = "robot"};
  for (std::size_t i = 130; i < truth.size(); ++i) {
    second[i] = test::drifted(truth[i], 5, 0.003);
    back.poses.push_back(poseOf(second[i]));
  }
  correctAndPatch(**live, **history, back, 30);
  EXPECT_EQ(differing(*(*live)->view(), *fromScratch(options, second)), 0U);
}

TEST(History, TheStoreKeepsItsBoundAndACorrectionPastItIsUnmatched) {
  test::TempDir dir;
  const std::vector<RawScan> scans = indoorScans(dir.path(), 60);
  ASSERT_EQ(scans.size(), 60U);
  const std::size_t one = encodeScanRecord(scans[0]).size();
  auto live = Engine::create({});
  ASSERT_TRUE(live);
  auto history = ScanHistory::create({.store = {.directory = dir.path() / "store",
                                                .max_bytes = 25 * one,
                                                .segment_bytes = 5 * one},
                                      .checkpoint_every = 10,
                                      .max_checkpoints = 100},
                                     (*live)->view());
  ASSERT_TRUE(history);
  for (const RawScan& s : scans) {
    ASSERT_TRUE((*live)->integrate(s));
    ASSERT_TRUE((*history)->record(s, (*live)->view()));
  }
  const ScanStore& store = (*history)->store();
  EXPECT_LE(store.bytes(), 25 * one);
  EXPECT_EQ(store.end(), 60U);
  EXPECT_EQ(store.first(), (*history)->oldestCorrectable());
  EXPECT_GE(store.first(), 30U);
  EXPECT_FALSE((*history)->checkpointBefore(store.first() - 1));

  PoseCorrection late{.sensor_id = "robot"};
  late.poses = {poseOf(scans[5]), poseOf(scans[59])};
  const CorrectionOutcome outcome = (*history)->correct(late);
  EXPECT_EQ(outcome.corrected, 1U);
  EXPECT_EQ(outcome.unmatched, 1U);
  EXPECT_EQ(outcome.earliest, 59U);

  (*history)->restart((*live)->view());
  EXPECT_EQ(store.bytes(), 0U);
  EXPECT_EQ((*history)->oldestCorrectable(), 60U);
}

TEST(History, ACorrectionWithABadPoseOrTooManyPosesIsRefused) {
  PoseCorrection c{.sensor_id = "robot", .poses = {{.stamp_ns = 1}}};
  EXPECT_TRUE(checkCorrection(c, {}));
  c.poses[0].q = {2, 0, 0, 0};
  EXPECT_FALSE(checkCorrection(c, {}));
  c.poses[0].q = {1, 0, 0, 0};
  c.poses[0].t[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(checkCorrection(c, {}));
  c.poses[0].t[1] = 1e9;
  EXPECT_FALSE(checkCorrection(c, {}));
  c.poses.assign(kMaxCorrectedPoses + 1, CorrectedPose{});
  EXPECT_FALSE(checkCorrection(c, {}));
  c.poses.clear();
  c.sensor_id.assign(kMaxSensorIdBytes + 1, 'x');
  EXPECT_FALSE(checkCorrection(c, {}));
}

TEST(History, KernelMapsAndDecayAreNotReintegrated) {
  auto view = MapView::fromMap(*makeMap(Backend::kGrid, 0.2).value(), 0);
  PipelineOptions kernel;
  kernel.kernel = kernel::KernelMethod::kAkimapRays;
  EXPECT_FALSE(Reintegration::create(kernel, {0, view}));
  PipelineOptions decay;
  decay.decay = DecayOptions{};
  EXPECT_FALSE(Reintegration::create(decay, {0, view}));
}

}  // namespace
}  // namespace densemap
