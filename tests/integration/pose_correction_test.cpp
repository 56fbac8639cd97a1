// Pose corrections end to end, the server as a process on loopback (domain 208): a robot whose
// odometry drifts over its last 200 scans, then a loop closure that corrects them. The server
// re-integrates in the background while more scans arrive and a client keeps querying; the
// corrected map it then serves equals, cell for cell, the map built from scratch with the
// corrected poses. Prints the re-integration's time per scan and the queries' p50/p99 while it
// ran.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/server/server_config.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/drift.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"

namespace densemap {
namespace {

using namespace std::chrono_literals;

constexpr std::uint32_t kDomain = 208;

/// The server's map built offline, from scratch, from `scans` in order (the server's own config).
std::shared_ptr<const MapView> fromScratch(const std::vector<RawScan>& scans,
                                           const std::filesystem::path& config) {
  auto cfg = server::loadServerConfig(config);
  EXPECT_TRUE(cfg) << cfg.error().message;
  auto options = server::pipelineOptions(*cfg);
  EXPECT_TRUE(options);
  auto engine = Engine::create(*options);
  EXPECT_TRUE(engine);
  for (const RawScan& s : scans) EXPECT_TRUE((*engine)->integrate(s));
  return (*engine)->view();
}

/// Cells in which the fetched map and `expected` differ.
std::size_t differing(const MapSnapshot& fetched, const MapView& expected) {
  const GridMap& map = testing::gridOf(fetched);
  GridMap expected_map(map.resolution(), map.sensorModel());
  expected.forEachKnown([&](const VoxelKey& k, float v) { expected_map.setLogOdds(k, v); });
  return diffMaps(map, expected_map).differing();
}

ServerStatus waitForStatus(Client& client, const std::function<bool(const ServerStatus&)>& done,
                           std::chrono::seconds timeout = 60s) {
  ServerStatus last;
  for (const auto deadline = std::chrono::steady_clock::now() + timeout;
       std::chrono::steady_clock::now() < deadline;) {
    if (auto s = client.status()) {
      last = *s;
      if (done(last)) return last;
    }
    std::this_thread::sleep_for(50ms);
  }
  ADD_FAILURE() << "status never reached the expected state";
  return last;
}

TEST(PoseCorrections, TheServerReintegratesACorrectedTrajectoryWhileScansAndQueriesGoOn) {
  test::TempDir dir;
  constexpr int kScans = 400, kCorrected = 200, kAfter = 20;
  auto truth =
      test::simulatedRawScans(dir.path(), test::smallIndoorDrive(kScans + kAfter, 90), "robot");
  ASSERT_EQ(truth.size(), std::size_t{kScans + kAfter});
  for (RawScan& s : truth) s.stamp_ns = static_cast<std::int64_t>(s.seq) * 100'000'000;
  std::vector<RawScan> live(truth.begin(), truth.begin() + kScans);
  for (int i = kScans - kCorrected; i < kScans; ++i) {
    live[i] = test::drifted(truth[i], i - (kScans - kCorrected) + 1, 0.002);
  }
  const std::vector<RawScan> after(truth.begin() + kScans, truth.end());

  test::ServerProcess server(dir.path(), kDomain,
                             "history { enabled: true directory: \"" +
                                 (dir.path() / "history").string() +
                                 "\" checkpoint_every: 50 max_checkpoints: 16 }\n"
                                 // Room for the scans that arrive while the worker swaps the
                                 // corrected map in (latest-wins would drop the oldest).
                                 "pipeline { queue_depth: 64 }\n");
  const auto config = dir.path() / "server.textproto";
  auto client = test::connectClient(kDomain);
  ASSERT_TRUE(client);
  test::replayScans(*client, live);
  auto drifted_map = client->fetchMap(kScans);
  ASSERT_TRUE(drifted_map) << drifted_map.error().message;
  EXPECT_EQ(differing(*drifted_map, *fromScratch(live, config)), 0U);

  std::vector<RawScan> corrected(truth.begin(), truth.begin() + kScans);
  const std::size_t drift_cells = differing(*drifted_map, *fromScratch(corrected, config));
  ASSERT_GT(drift_cells, 10000U) << "the drift must show in the map for the check to mean "
                                    "anything";

  // A client queries points near the path the whole time.
  std::vector<float> xyz;
  for (const RawScan& raw : {live[50], live[250], live[390]}) {
    xyz.insert(xyz.end(), raw.xyz.begin(), raw.xyz.begin() + 3000);
  }
  std::atomic<bool> querying{true};
  std::vector<double> query_ms;
  std::size_t query_errors = 0;
  std::thread queries([&] {
    auto q = test::connectClient(kDomain);
    if (!q) return;
    while (querying.load()) {
      const auto t0 = std::chrono::steady_clock::now();
      auto answer = q->queryPoints(std::span<const float>(xyz));
      query_ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      query_errors += !answer;
    }
  });

  PoseCorrection correction{.sensor_id = "robot"};
  for (int i = kScans - kCorrected; i < kScans; ++i) {
    correction.poses.push_back(
        {truth[i].stamp_ns, truth[i].t_world_sensor, truth[i].q_world_sensor});
  }
  correction.poses.push_back({1, {0, 0, 0}, {1, 0, 0, 0}});  // names no scan
  ASSERT_TRUE(client->publishPoseCorrection(correction));
  // More scans arrive while it re-integrates: they go into the live map and are caught up.
  for (const RawScan& raw : after) {
    ASSERT_TRUE(client->publishScan(raw));
    std::this_thread::sleep_for(20ms);
  }
  const ServerStatus status = waitForStatus(*client, [&](const ServerStatus& s) {
    return s.history.reintegrations == 1 && s.integrated == std::size_t{kScans + kAfter};
  });
  querying = false;
  queries.join();

  corrected.insert(corrected.end(), after.begin(), after.end());
  auto fetched = client->fetchMap(status.history.last_version);
  ASSERT_TRUE(fetched) << fetched.error().message;
  EXPECT_EQ(differing(*fetched, *fromScratch(corrected, config)), 0U)
      << "the served map against the map built from scratch with the corrected poses";
  EXPECT_EQ(status.history.corrections, 1U);
  EXPECT_EQ(status.history.corrected_scans, std::size_t{kCorrected});
  EXPECT_EQ(status.history.unmatched_poses, 1U);
  EXPECT_EQ(status.history.corrections_rejected, 0U);
  EXPECT_FALSE(status.history.reintegrating);
  EXPECT_EQ(status.history.scans, std::size_t{kScans + kAfter});
  EXPECT_GT(status.history.bytes, 0U);
  EXPECT_EQ(query_errors, 0U);
  ASSERT_FALSE(query_ms.empty());
  std::sort(query_ms.begin(), query_ms.end());
  std::printf(
      "pose correction: %d of %d scans corrected (%zu cells drifted), re-integrated at %.2f ms "
      "a scan; %zu point queries (%zu points) meanwhile: p50 %.2f ms, p99 %.2f ms; %.1f MB "
      "of scans kept\n",
      kCorrected, kScans, drift_cells, status.history.last_ms_per_scan, query_ms.size(),
      xyz.size() / 3, nearestRank(query_ms, 0.5), nearestRank(query_ms, 0.99),
      static_cast<double>(status.history.bytes) / 1e6);

  // A malformed correction is refused and counted; the map is unchanged.
  PoseCorrection bad{.sensor_id = "robot",
                     .poses = {{truth[10].stamp_ns, {0, 0, 0}, {3, 0, 0, 0}}}};
  ASSERT_TRUE(client->publishPoseCorrection(bad));
  const ServerStatus refused = waitForStatus(
      *client, [](const ServerStatus& s) { return s.history.corrections_rejected == 1; });
  EXPECT_NE(refused.history.last_error.find("quaternion"), std::string::npos)
      << refused.history.last_error;
  EXPECT_EQ(refused.map_version, status.map_version);
  EXPECT_EQ(server.stop(), 0);
}

}  // namespace
}  // namespace densemap
