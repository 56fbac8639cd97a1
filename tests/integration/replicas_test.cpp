// Replicas end to end, as separate processes on loopback: two servers on one DDS domain
// (dds.instance "a" and "b") read the same 1,000 scans from one robot and publish the same
// changes at every version; a client that asks "a" with "b" as its replica is answered by "b"
// within 2 s of "a" being killed with SIGKILL. A replica started late (dds.catch_up_from) while
// scans go on takes its peer's map and the scans it lacks: both then hold the same map at the
// same version.
#include <gtest/gtest.h>

#include <cstdio>
#include <map>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"

namespace densemap {
namespace {

using namespace std::chrono_literals;

constexpr std::uint32_t kDomain = 206;
constexpr std::uint32_t kCatchUpDomain = 209;

/// A version's changes, in a canonical order (cells sorted by key).
std::vector<std::tuple<std::uint64_t, float, bool>> canonical(const CellChanges& changes) {
  std::vector<std::tuple<std::uint64_t, float, bool>> out;
  out.reserve(changes.size());
  for (const CellChange& c : changes) out.emplace_back(c.key.packed(), c.log_odds, c.known);
  std::sort(out.begin(), out.end());
  return out;
}

TEST(Replicas, TwoReplicasPublishTheSameChangesAtEveryVersionAndAClientFailsOver) {
  test::TempDir dir;
  const auto raws = test::simulatedRawScans(dir.path(), test::smallIndoorDrive(1000, 90), "robot");
  ASSERT_EQ(raws.size(), 1000U);
  std::filesystem::create_directory(dir.path() / "a");
  std::filesystem::create_directory(dir.path() / "b");
  test::ServerProcess a(dir.path() / "a", kDomain, "", false, 0, "", "instance: \"a\"");
  test::ServerProcess b(dir.path() / "b", kDomain, "", false, 0, "", "instance: \"b\"");
  std::map<std::string, std::unique_ptr<Client>> watch;
  for (const char* name : {"a", "b"}) {
    auto c = Client::create(
        {.domain_id = kDomain, .timeout = 10s, .subscribe_deltas = true, .instance = name});
    ASSERT_TRUE(c) << c.error().message;
    ASSERT_TRUE((*c)->waitForServer());
    watch[name] = std::move(*c);
  }
  // Each version's changes as each replica published them.
  std::map<std::string,
           std::map<std::uint64_t, std::vector<std::tuple<std::uint64_t, float, bool>>>>
      versions;
  const auto poll = [&] {
    for (auto& [name, client] : watch) {
      client->pollDeltas(
          [&](const DeltaInfo& d) { versions[name][d.new_version] = canonical(d.changes); });
    }
  };
  for (const RawScan& raw : raws) {
    ASSERT_TRUE(watch["a"]->publishScan(raw));  // the scan topic is every replica's
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    while ((versions["a"].size() < raw.seq || versions["b"].size() < raw.seq) &&
           std::chrono::steady_clock::now() < deadline) {
      poll();
      std::this_thread::sleep_for(1ms);
    }
    ASSERT_EQ(versions["a"].size(), raw.seq);
    ASSERT_EQ(versions["b"].size(), raw.seq);
  }
  std::size_t differing = 0, cells = 0;
  for (std::uint64_t v = 1; v <= raws.size(); ++v) {
    differing += versions["a"][v] != versions["b"][v];
    cells += versions["a"][v].size();
  }
  EXPECT_EQ(differing, 0U) << "versions whose changes differ between the replicas";
  EXPECT_GT(cells, 100000U);
  const auto status_a = watch["a"]->status(), status_b = watch["b"]->status();
  ASSERT_TRUE(status_a && status_b);

  // Failover: a client of "a" with "b" as its replica.
  auto client =
      Client::create({.domain_id = kDomain, .timeout = 700ms, .instance = "a", .replicas = {"b"}});
  ASSERT_TRUE(client) << client.error().message;
  ASSERT_TRUE((*client)->waitForServer());
  std::vector<float> xyz;
  for (const RawScan& raw : {raws[100], raws[500], raws[900]}) {
    for (int k = 0; k < 3; ++k) xyz.push_back(static_cast<float>(raw.t_world_sensor[k]));
    xyz.insert(xyz.end(), raw.xyz.begin(), raw.xyz.begin() + 3000);  // near the sensor
  }
  auto before = (*client)->queryPoints(std::span<const float>(xyz));
  ASSERT_TRUE(before) << before.error().message;
  a.kill9();
  const auto killed = std::chrono::steady_clock::now();
  auto after = (*client)->queryPoints(std::span<const float>(xyz));
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - killed).count();
  ASSERT_TRUE(after) << after.error().message;
  EXPECT_LT(took_s, 2.0);
  std::printf(
      "replicas: %zu versions, %zu changed cells, identical; answered by \"b\" %.2f s "
      "after \"a\" was killed\n",
      raws.size(), cells, took_s);
  auto from_b = watch["b"]->queryPoints(std::span<const float>(xyz));
  ASSERT_TRUE(from_b);
  EXPECT_EQ(after->log_odds, from_b->log_odds);
  EXPECT_EQ(after->log_odds, before->log_odds);  // the same map: "a" answered it before
  auto again = (*client)->castRay({0, 0, 1}, {1, 0, 0}, 20.0F);
  EXPECT_TRUE(again) << again.error().message;
  EXPECT_EQ(b.stop(), 0);
}

TEST(Replicas, AReplicaStartedLateCatchesUpFromItsPeerToTheSameMapAtTheSameVersion) {
  test::TempDir dir;
  constexpr int kBefore = 300, kDuring = 200;
  auto raws =
      test::simulatedRawScans(dir.path(), test::smallIndoorDrive(kBefore + kDuring, 90), "robot");
  ASSERT_EQ(raws.size(), std::size_t{kBefore + kDuring});
  for (RawScan& raw : raws) raw.stamp_ns = static_cast<std::int64_t>(raw.seq) * 100'000'000;
  std::filesystem::create_directory(dir.path() / "a");
  std::filesystem::create_directory(dir.path() / "b");
  // Room in the queue for the scans that arrive while "a" swaps its map (latest-wins would drop
  // the oldest, and a scan one replica drops parts them).
  const std::string queue = "pipeline { queue_depth: 64 }\n";
  test::ServerProcess b(dir.path() / "b", kCatchUpDomain, queue, false, 0, "", "instance: \"b\"");
  auto to_b = Client::create({.domain_id = kCatchUpDomain, .timeout = 10s, .instance = "b"});
  ASSERT_TRUE(to_b) << to_b.error().message;
  ASSERT_TRUE((*to_b)->waitForServer());
  test::replayScans(**to_b, std::vector<RawScan>(raws.begin(), raws.begin() + kBefore));

  // "a" starts while the robot goes on: the scans of its first seconds come before, during and
  // after its fetch of "b"'s map.
  test::ServerProcess a(dir.path() / "a", kCatchUpDomain, queue, true, 0, "",
                        "instance: \"a\" catch_up_from: \"b\"");
  for (int i = kBefore; i < kBefore + kDuring; ++i) {
    ASSERT_TRUE((*to_b)->publishScan(raws[i]));
    std::this_thread::sleep_for(20ms);
  }
  auto to_a = Client::create({.domain_id = kCatchUpDomain, .timeout = 10s, .instance = "a"});
  ASSERT_TRUE(to_a) << to_a.error().message;
  ASSERT_TRUE((*to_a)->waitForServer());
  const std::uint64_t last = kBefore + kDuring;
  std::uint64_t version_a = 0, version_b = 0;
  for (const auto deadline = std::chrono::steady_clock::now() + 30s;
       (version_a != last || version_b != last) && std::chrono::steady_clock::now() < deadline;) {
    if (auto s = (*to_a)->status()) version_a = s->map_version;
    if (auto s = (*to_b)->status()) version_b = s->map_version;
    std::this_thread::sleep_for(50ms);
  }
  ASSERT_EQ(version_b, last);
  ASSERT_EQ(version_a, last) << a.log();
  EXPECT_NE(a.log().find("caught up"), std::string::npos) << a.log();
  auto map_a = (*to_a)->fetchMap(last), map_b = (*to_b)->fetchMap(last);
  ASSERT_TRUE(map_a && map_b);
  EXPECT_EQ(map_a->version(), map_b->version());
  const GridMap& grid_a = testing::gridOf(*map_a);
  const MapDiff diff = diffMaps(grid_a, testing::gridOf(*map_b));
  EXPECT_EQ(diff.differing(), 0U) << diff.only_in_a << " / " << diff.only_in_b << " / "
                                  << diff.value_mismatch << " of " << diff.union_cells;
  EXPECT_GT(grid_a.knownCells(), 100000U);
  ASSERT_EQ(map_b->lastStamps().size(), 1U);
  EXPECT_EQ(map_b->lastStamps()[0], std::make_pair(std::string("robot"), raws[last - 1].stamp_ns));
  std::printf("catch-up: %s", a.log().substr(a.log().find("caught up")).c_str());
  EXPECT_EQ(a.stop(), 0);
  EXPECT_EQ(b.stop(), 0);
}

}  // namespace
}  // namespace densemap
