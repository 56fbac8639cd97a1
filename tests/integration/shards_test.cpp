// Spatial shards end to end, as separate processes on loopback: a server over all of space and
// two whose map.bounds split it (on one DDS domain, each its own dds.instance), fed the same
// scans. Together the
// shards hold the single server's map cell for cell, their manifests say where each is, and
// ShardedClient's point, box and ray queries across the border equal the single server's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "densemap/client/client.hpp"
#include "densemap/client/sharded_client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"

namespace densemap {
namespace {

using namespace std::chrono_literals;

// The single server on a domain of its own; the two shards on one domain, each with its own
// dds.instance, so that every scan reaches both (DDS fan-out).
constexpr std::uint32_t kSingle = 202, kShards = 203;

std::string boundsConfig(float min_x, float max_x) {
  return "bounds { min_x: " + std::to_string(min_x) +
         " min_y: -1000 min_z: -100 max_x: " + std::to_string(max_x) + " max_y: 1000 max_z: 100 }";
}

TEST(Shards, TwoShardsHoldTheSingleServersMapAndTheirRoutedQueriesEqualItsAnswers) {
  test::TempDir dir;
  const auto raws = test::simulatedRawScans(dir.path(), test::smallIndoorDrive(6, 300), "front");
  ASSERT_EQ(raws.size(), 6U);
  // The split: between the first and last scan's origins, inside a block (a block belongs to
  // the shard its centre lies in).
  const float split = static_cast<float>(
      0.5 * (raws.front().t_world_sensor[0] + raws.back().t_world_sensor[0]) + 0.3);
  for (const char* name : {"single", "west", "east"})
    std::filesystem::create_directory(dir.path() / name);
  test::ServerProcess single(dir.path() / "single", kSingle);
  test::ServerProcess west(dir.path() / "west", kShards, "", false, 0, boundsConfig(-1000, split),
                           "instance: \"west\"");
  test::ServerProcess east(dir.path() / "east", kShards, "", false, 0, boundsConfig(split, 1000),
                           "instance: \"east\"");
  const ClientOptions single_options{.domain_id = kSingle, .timeout = 10s},
      west_options{.domain_id = kShards, .timeout = 10s, .instance = "west"},
      east_options{.domain_id = kShards, .timeout = 10s, .instance = "east"};
  std::vector<std::unique_ptr<Client>> clients;
  for (const ClientOptions& o : {single_options, west_options, east_options}) {
    auto c = Client::create(o);
    ASSERT_TRUE(c) << c.error().message;
    ASSERT_TRUE((*c)->waitForServer());
    clients.push_back(std::move(*c));
  }
  // Once to the single server, once to the shards' domain: both shards read every scan.
  test::replayScans(*clients[0], raws);
  test::replayScans(*clients[1], raws);

  // The manifests say where each server's map is.
  auto single_manifest = clients[0]->manifest();
  auto west_manifest = clients[1]->manifest();
  ASSERT_TRUE(single_manifest && west_manifest);
  EXPECT_FALSE(single_manifest->bounds);
  ASSERT_TRUE(west_manifest->bounds);
  EXPECT_EQ(west_manifest->bounds->second.x(), split);
  EXPECT_EQ(west_manifest->bounds->first.y(), -1000.0F);

  // Together the shards hold the single server's map, cell for cell, each cell once.
  auto whole = clients[0]->fetchMap(raws.size());
  auto west_map = clients[1]->fetchMap(raws.size());
  auto east_map = clients[2]->fetchMap(raws.size());
  ASSERT_TRUE(whole && west_map && east_map);
  const GridMap& w = testing::gridOf(*west_map);
  const GridMap& e = testing::gridOf(*east_map);
  ASSERT_GT(w.knownCells(), 1000U);
  ASSERT_GT(e.knownCells(), 1000U);
  GridMap both(w.resolution(), w.sensorModel());
  std::size_t twice = 0;
  w.forEachKnown([&](const VoxelKey& k, float v) { both.setLogOdds(k, v); });
  e.forEachKnown([&](const VoxelKey& k, float v) {
    twice += both.logOdds(k).has_value();
    both.setLogOdds(k, v);
  });
  EXPECT_EQ(twice, 0U);
  const MapDiff diff = diffMaps(testing::gridOf(*whole), both);
  EXPECT_EQ(diff.differing(), 0U) << diff.only_in_a << " / " << diff.only_in_b << " / "
                                  << diff.value_mismatch << " of " << diff.union_cells;

  // Queries across the border, routed, equal the single server's answers.
  auto sharded = ShardedClient::create({west_options, east_options});
  ASSERT_TRUE(sharded) << sharded.error().message;
  const Point3f centre(split, static_cast<float>(raws.front().t_world_sensor[1]),
                       static_cast<float>(raws.front().t_world_sensor[2]));
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-8.0F, 8.0F), uz(-1.0F, 3.0F);
  std::vector<float> xyz;
  for (int i = 0; i < 5000; ++i) {
    xyz.insert(xyz.end(), {centre.x() + u(rng), centre.y() + u(rng), uz(rng)});
  }
  auto routed = (*sharded)->queryPoints(xyz);
  auto direct = clients[0]->queryPoints(std::span<const float>(xyz));
  ASSERT_TRUE(routed && direct);
  EXPECT_EQ(routed->states, direct->states);
  EXPECT_EQ(routed->log_odds, direct->log_odds);
  EXPECT_GT(std::count(direct->states.begin(), direct->states.end(), CellState::kOccupied), 50);
  std::set<std::size_t> owners;
  for (std::size_t k = 0; k < xyz.size() / 3; ++k) {
    if (auto o = (*sharded)->ownerOf({xyz[3 * k], xyz[3 * k + 1], xyz[3 * k + 2]}))
      owners.insert(*o);
  }
  EXPECT_EQ(owners.size(), 2U);
  const auto sorted = [](std::vector<Point3f> v) {
    std::sort(v.begin(), v.end(), [](const Point3f& a, const Point3f& b) {
      return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
    });
    return v;
  };
  for (float half : {0.7F, 2.5F, 6.0F}) {
    const Point3f lo = centre - Point3f(half, half, 1.5F), hi = centre + Point3f(half, half, 1.5F);
    auto a = (*sharded)->queryBox(lo, hi, 1'000'000);
    auto b = clients[0]->queryBox(lo, hi, 1'000'000);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->occupied, b->occupied) << half;
    EXPECT_EQ(a->free, b->free) << half;
    EXPECT_EQ(a->unknown, b->unknown) << half;
    EXPECT_EQ(sorted(a->occupied_centers), sorted(b->occupied_centers)) << half;
  }
  int hits = 0;
  for (int i = 0; i < 64; ++i) {
    const float angle = static_cast<float>(i) * 0.0981748F;  // 64 headings around the circle
    const Point3f origin(centre.x() - 3.0F, centre.y(), centre.z());
    const Point3f direction(std::cos(angle), std::sin(angle), -0.05F);
    auto a = (*sharded)->castRay(origin, direction, 20.0F);
    auto b = clients[0]->castRay(origin, direction, 20.0F);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->ray.hit, b->ray.hit) << i;
    if (a->ray.hit && b->ray.hit) {
      EXPECT_EQ(a->ray.hit_center, b->ray.hit_center) << i;
      EXPECT_EQ(a->ray.distance, b->ray.distance) << i;
    }
    hits += b->ray.hit;
  }
  EXPECT_GT(hits, 32);

  // A server over all of space cannot be a shard beside others.
  auto mixed = ShardedClient::create({single_options, west_options});
  ASSERT_FALSE(mixed);
  EXPECT_NE(mixed.error().message.find("no map.bounds"), std::string::npos)
      << mixed.error().message;
}

// A manifest is outside bytes too: a box that is not finite or is inverted, or a resolution
// that is not positive, is an error of Client::manifest, never a shard's box.
TEST(Shards, AManifestWithAMalformedBoxOrResolutionIsRefused) {
  constexpr std::uint32_t kDomain = 207;
  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant) << participant.error().message;
  auto topics = dds::Topics::create(*participant);
  ASSERT_TRUE(topics);
  auto writer = dds::createWriter(*participant, topics->manifest, dds::kLatestStateQos);
  ASSERT_TRUE(writer);
  auto client = Client::create({.domain_id = kDomain, .timeout = 3s});
  ASSERT_TRUE(client) << client.error().message;
  const auto send = [&](densemap_msgs_MapManifest m) {
    ASSERT_TRUE(dds::write(*writer, &m));
    std::this_thread::sleep_for(200ms);
  };
  densemap_msgs_MapManifest good{};
  good.version = 3;
  good.resolution = 0.2;
  good.bounded = true;
  good.min_x = good.min_y = good.min_z = -1;
  good.max_x = good.max_y = good.max_z = 1;
  send(good);
  auto read = (*client)->manifest();
  ASSERT_TRUE(read) << read.error().message;
  ASSERT_TRUE(read->bounds);
  EXPECT_EQ(read->bounds->second.x(), 1.0F);
  auto nan_box = good;
  nan_box.max_y = std::nan("");
  auto inverted = good;
  inverted.min_z = 5;
  auto infinite = good;
  infinite.min_x = -HUGE_VAL;
  auto no_resolution = good;
  no_resolution.resolution = 0;
  for (const auto& bad : {nan_box, inverted, infinite, no_resolution}) {
    send(bad);
    auto refused = (*client)->manifest();
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.error().message.find("malformed"), std::string::npos)
        << refused.error().message;
  }
}

}  // namespace
}  // namespace densemap
