// densemap-server and its clients as separate processes on loopback, each test on its own DDS
// domain (scripts/test.sh runs the suite in a private network namespace when it can).
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>

#include <atomic>
#include <cmath>
#include <fstream>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/mapper/mapper.hpp"
#include "densemap/pipeline/scan_validator.hpp"
#include "densemap/planner/distance_query.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"
#include "densemap/upsample/interpolation.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap_msgs.h"

extern char** environ;

namespace densemap {
namespace {

using namespace std::chrono_literals;

using test::ServerProcess;

std::unique_ptr<Client> connect(std::uint32_t domain) {
  return test::connectClient(domain, /*subscribe_deltas=*/true);
}

std::vector<RawScan> simulatedScans(const std::filesystem::path& dir, int n) {
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 600;
  o.scans = n;
  o.ground_truth_resolution_m = 0;
  return test::simulatedRawScans(dir, o, "test");
}

/// What the server must hold after these scans: the offline map of the same validated scans,
/// each densified first when `densify` is given.
std::unique_ptr<GridMap> offlineMap(const std::vector<RawScan>& raws,
                                    const upsample::UpsampleOptions* densify = nullptr) {
  auto map = std::make_unique<GridMap>(0.2, SensorModel{});
  Integrator integrator({.max_range_m = 25.0});
  for (const auto& raw : raws) {
    Scan scan = *validateScan(raw, ScanLimits{});
    if (densify) scan.points = upsample::upsamplePoints(scan.points, *densify);
    integrator.integrate(*map, scan.pointsWorld(), scan.originWorld());
  }
  return map;
}

/// Publishes scans one at a time, each after the previous one's delta; returns the deltas.
std::vector<DeltaInfo> replay(Client& client, const std::vector<RawScan>& raws) {
  std::vector<DeltaInfo> deltas;
  for (const auto& raw : raws) {
    EXPECT_TRUE(client.publishScan(raw));
    const auto deadline = std::chrono::steady_clock::now() + 20s;
    bool seen = false;
    while (!seen && std::chrono::steady_clock::now() < deadline) {
      client.pollDeltas([&](const DeltaInfo& d) {
        deltas.push_back(d);
        seen = seen || d.scan_seq == raw.seq;
      });
      std::this_thread::sleep_for(5ms);
    }
    EXPECT_TRUE(seen) << "no delta for scan " << raw.seq;
  }
  return deltas;
}

TEST(Server, ReplayedScansGiveTheOfflineMapExactlyForQueriesTilesAndDeltas) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 4);
  ServerProcess server(dir.path(), 141);
  auto client = connect(141);
  ASSERT_TRUE(client);
  const auto deltas = replay(*client, raws);
  const auto offline = offlineMap(raws);

  // Point queries at every known cell (and a few unknown ones) return the offline values.
  std::vector<Point3f> points;
  std::vector<float> expected;
  offline->forEachKnown([&](const VoxelKey& k, float v) {
    points.push_back(offline->grid().keyToPoint(k));
    expected.push_back(v);
  });
  points.emplace_back(500.0F, 500.0F, 500.0F);
  auto answer = client->queryPoints(points);
  ASSERT_TRUE(answer) << answer.error().message;
  ASSERT_EQ(answer->log_odds.size(), points.size());
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < expected.size(); ++i)
    mismatches += answer->log_odds[i] != expected[i];
  EXPECT_EQ(mismatches, 0U);
  EXPECT_FALSE(answer->log_odds.back().has_value());
  EXPECT_EQ(answer->map_version, raws.size());

  // Deltas applied in order to an empty map reproduce every version, ending at the offline map.
  GridMap rebuilt(0.2, SensorModel{});
  std::uint64_t version = 0;
  for (const DeltaInfo& d : deltas) {
    EXPECT_EQ(d.base_version, version);
    for (const CellChange& c : d.changes) rebuilt.setLogOdds(c.key, c.log_odds);
    version = d.new_version;
  }
  EXPECT_EQ(diffMaps(rebuilt, *offline).differing(), 0U);

  // A late joiner rebuilds the same map from the transient-local tiles.
  auto late = connect(141);
  ASSERT_TRUE(late);
  auto fetched = late->fetchMap(raws.size());
  ASSERT_TRUE(fetched) << fetched.error().message;
  EXPECT_EQ(diffMaps(testing::gridOf(*fetched), *offline).differing(), 0U);

  // Box and ray queries agree with core on the same map.
  auto box = client->queryBox(Point3f(0, 5, 0), Point3f(10, 15, 2.5F));
  ASSERT_TRUE(box);
  const auto view = MapView::fromMap(*offline, raws.size());
  auto core_box = queryBox(*view, Point3f(0, 5, 0), Point3f(10, 15, 2.5F), 1u << 30, 0);
  EXPECT_EQ(box->occupied, core_box->occupied);
  EXPECT_EQ(box->free, core_box->free);
  auto ray = client->castRay(Point3f(5, 10, 1.2F), Point3f(0, 1, 0), 20.0F);
  auto core_ray = castRay(*view, Point3f(5, 10, 1.2F), Point3f(0, 1, 0), 20.0F);
  ASSERT_TRUE(ray && core_ray);
  EXPECT_EQ(ray->ray.hit, core_ray->hit);
  EXPECT_EQ(ray->ray.hit_center, core_ray->hit_center);
  EXPECT_EQ(server.stop(), 0);
}

// The server's distance field (esdf) and path checks answer over DDS what core answers on
// the offline map of the same scans; a server without the field says so; bad requests are
// refused with their reason and counted.
TEST(Server, DistanceAndPathQueriesEqualCoreOnTheOfflineMap) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 3);
  ServerProcess server(dir.path(), 223, "esdf { enabled: true max_distance_m: 1.0 }\n");
  auto client = connect(223);
  ASSERT_TRUE(client);
  replay(*client, raws);
  const auto offline = offlineMap(raws);
  const auto view = MapView::fromMap(*offline, raws.size());
  auto field = DistanceField::create(0.2, {.max_distance_m = 1.0});
  ASSERT_TRUE(field);
  field->rebuild(*view);
  std::vector<float> xyz;
  for (float x = 0.1F; x < 10.0F; x += 0.37F) {
    for (float y = 5.1F; y < 15.0F; y += 0.41F) xyz.insert(xyz.end(), {x, y, 1.1F});
  }
  for (const bool unknown : {false, true}) {
    const DistanceQueryOptions o{.unknown_as_occupied = unknown, .interpolate = unknown};
    auto remote = client->queryDistances(xyz, o);
    ASSERT_TRUE(remote) << remote.error().message;
    auto local = queryDistances(*field, *view, xyz, o, 1'000'000, serialRunner());
    ASSERT_TRUE(local);
    EXPECT_EQ(remote->map_version, raws.size());
    EXPECT_EQ(remote->max_distance, 1.0F);
    EXPECT_EQ(remote->distances, local->distances);
    EXPECT_EQ(remote->gradients, local->gradients);
    ASSERT_EQ(remote->nearest.size(), local->nearest.size());
    for (std::size_t i = 0; i < local->nearest.size(); ++i) {
      if (std::isnan(local->nearest[i])) {
        EXPECT_TRUE(std::isnan(remote->nearest[i]));
      } else {
        EXPECT_EQ(remote->nearest[i], local->nearest[i]);
      }
    }
  }
  const std::vector<float> path{1.0F, 8.0F, 1.1F, 9.0F, 12.0F, 1.1F, 2.0F, 14.0F, 1.5F};
  auto remote = client->checkPath(path, 0.3F);
  ASSERT_TRUE(remote) << remote.error().message;
  auto local = checkPath(*view, path, 0.3F);
  ASSERT_TRUE(local);
  EXPECT_EQ(remote->state, local->state);
  ASSERT_EQ(remote->occupied.has_value(), local->occupied.has_value());
  if (local->occupied) {
    EXPECT_EQ(remote->occupied->arc_length, local->occupied->arc_length);
    EXPECT_EQ(remote->occupied->center, local->occupied->center);
  }
  EXPECT_DOUBLE_EQ(remote->length_m, local->length_m);

  // Oriented boxes (a footprint turning along the path) and the dense distance box.
  std::vector<OrientedBox> boxes;
  for (int i = 0; i < 20; ++i) {
    OrientedBox b;
    b.center = Point3f(1.0F + 0.4F * static_cast<float>(i), 8.0F + 0.2F * static_cast<float>(i), 1.1F);
    b.half_extents = Point3f(0.4F, 0.25F, 0.3F);
    b.rotation = Eigen::Quaternionf(Eigen::AngleAxisf(0.1F * static_cast<float>(i), Eigen::Vector3f::UnitZ()));
    boxes.push_back(b);
  }
  auto remote_boxes = client->checkBoxes(boxes);
  ASSERT_TRUE(remote_boxes) << remote_boxes.error().message;
  auto local_boxes = checkBoxes(*view, boxes);
  ASSERT_TRUE(local_boxes);
  EXPECT_EQ(remote_boxes->state, local_boxes->state);
  ASSERT_EQ(remote_boxes->occupied.has_value(), local_boxes->occupied.has_value());
  if (local_boxes->occupied) {
    EXPECT_EQ(remote_boxes->occupied->index, local_boxes->occupied->index);
    EXPECT_EQ(remote_boxes->occupied->center, local_boxes->occupied->center);
  }
  ASSERT_EQ(remote_boxes->unknown.has_value(), local_boxes->unknown.has_value());
  for (const bool unknown : {false, true}) {
    auto remote_box = client->distanceBox(Point3f(1, 6, 0.5F), Point3f(6, 12, 2), unknown);
    ASSERT_TRUE(remote_box) << remote_box.error().message;
    auto local_box =
        exportDistanceBox(*field, *view, Point3f(1, 6, 0.5F), Point3f(6, 12, 2), unknown, 1u << 24);
    ASSERT_TRUE(local_box);
    EXPECT_EQ(remote_box->map_version, raws.size());
    EXPECT_EQ(remote_box->size, local_box->size);
    EXPECT_EQ(remote_box->min_center, view->grid().keyToPoint(local_box->min));
    EXPECT_EQ(remote_box->distances, local_box->distances);
  }

  // Refusals: their reasons, counted.
  auto huge_box = client->distanceBox(Point3f(-500, -500, -500), Point3f(500, 500, 500));
  ASSERT_FALSE(huge_box);
  EXPECT_NE(huge_box.error().message.find("cells"), std::string::npos) << huge_box.error().message;
  std::vector<OrientedBox> bad_boxes = boxes;
  bad_boxes[3].rotation = Eigen::Quaternionf(2.0F, 0.0F, 0.0F, 0.0F);
  auto bad = client->checkBoxes(bad_boxes);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("quaternion"), std::string::npos) << bad.error().message;
  auto nan = client->queryDistances(std::vector<float>{0, 0, std::nanf("")});
  ASSERT_FALSE(nan);
  EXPECT_NE(nan.error().message.find("NaN"), std::string::npos) << nan.error().message;
  auto negative = client->checkPath(path, -1.0F);
  ASSERT_FALSE(negative);
  EXPECT_NE(negative.error().message.find("radius"), std::string::npos);
  auto long_path = client->checkPath(std::vector<float>(3 * 100'001, 0.0F), 0.1F);
  ASSERT_FALSE(long_path);
  // The status (1 Hz) counts the four refused on the server (the long path never left).
  std::uint64_t rejected = 0;
  for (int i = 0; i < 40 && rejected < 4; ++i) {
    std::this_thread::sleep_for(100ms);
    if (auto status = client->status()) rejected = status->queries_rejected;
  }
  EXPECT_GE(rejected, 4U);
  EXPECT_EQ(server.stop(), 0);

  // A server without the field says so.
  test::TempDir plain_dir;
  ServerProcess plain(plain_dir.path(), 224);
  auto plain_client = connect(224);
  ASSERT_TRUE(plain_client);
  auto none = plain_client->queryDistances(xyz);
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().message.find("esdf"), std::string::npos) << none.error().message;
  auto no_box = plain_client->distanceBox(Point3f(0, 0, 0), Point3f(1, 1, 1));
  ASSERT_FALSE(no_box);
  EXPECT_NE(no_box.error().message.find("esdf"), std::string::npos) << no_box.error().message;
  EXPECT_EQ(plain.stop(), 0);
}

// map.decay with the scans' stamps as the clock: the server's map after each replayed scan of
// a scene with people walking equals a Mapper's with the same decay and stamps, and the status
// counts the cells that decayed to unknown.
TEST(Server, DecayFollowsTheScanStampsAsTheMapperDoes) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 600;
  o.scans = 12;
  o.walkers = 2;
  o.ground_truth_resolution_m = 0;
  auto raws = test::simulatedRawScans(dir.path(), o, "test");
  ASSERT_EQ(raws.size(), 12U);
  for (std::size_t i = 0; i < raws.size(); ++i) {
    raws[i].stamp_ns = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(i) * 100'000'000;
  }
  ServerProcess server(dir.path(), 213, "", false, 0,
                       "decay { enabled: true after_s: 0.2 period_s: 0.1 clock: \"stamp\" }");
  auto client = connect(213);
  ASSERT_TRUE(client);
  replay(*client, raws);

  MapperOptions m;
  m.resolution_m = 0.2;
  m.max_range_m = 25.0;
  m.threads = 2;
  m.decay = DecayOptions{.after_s = 0.2, .period_s = 0.1};
  auto mapper = Mapper::create(m);
  ASSERT_TRUE(mapper);
  std::size_t erased = 0;
  for (const RawScan& raw : raws) {
    const Scan scan = *validateScan(raw, ScanLimits{});
    auto r = mapper->insertPointCloud(scan.pointsWorld(), scan.originWorld(),
                                      static_cast<double>(raw.stamp_ns) * 1e-9);
    ASSERT_TRUE(r);
    erased += r->decay_erased_cells;
  }
  ASSERT_GT(erased, 0U) << "the sequence should make cells decay";
  auto fetched = client->fetchMap(raws.size());
  ASSERT_TRUE(fetched) << fetched.error().message;
  const GridMap& served = testing::gridOf(*fetched);
  EXPECT_EQ(served.knownCells(), mapper->knownCells());
  std::size_t differ = 0;
  mapper->forEachCell(CellFilter::kKnown, [&](const Point3f& centre, float v) {
    const auto key = served.grid().pointToKey(centre);
    const auto theirs = key ? served.logOdds(*key) : std::nullopt;
    differ += !theirs || *theirs != v;
  });
  EXPECT_EQ(differ, 0U);
  std::uint64_t decayed = 0;
  for (int i = 0; i < 40 && decayed < erased; ++i) {
    if (auto status = client->status()) decayed = status->decayed_cells;
    if (decayed < erased) std::this_thread::sleep_for(100ms);
  }
  EXPECT_EQ(decayed, erased);
  EXPECT_EQ(server.stop(), 0);
}

TEST(Server, IlnUpsampleStageGivesTheOfflineDensifiedMap) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 3);  // vlp16: 16 beams, +-15 deg, 600 columns
  ServerProcess server(dir.path(), 166,
                       "upsample { enabled: true method: \"iln\" model: \"" DENSEMAP_ILN_MODEL
                       "\" input_rows: 16 input_cols: 600 output_rows: 61 output_cols: 600 }\n");
  auto client = connect(166);
  ASSERT_TRUE(client);
  replay(*client, raws);
  const auto densify = upsample::makeUpsampleOptions("iln", {.rows = 16, .cols = 600},
                                                     {.rows = 61, .cols = 600}, DENSEMAP_ILN_MODEL);
  ASSERT_TRUE(densify) << densify.error().message;
  const auto offline = offlineMap(raws, &*densify);
  EXPECT_GT(offline->knownCells(), offlineMap(raws)->knownCells());
  auto fetched = client->fetchMap(raws.size());
  ASSERT_TRUE(fetched) << fetched.error().message;
  EXPECT_EQ(diffMaps(testing::gridOf(*fetched), *offline).differing(), 0U);
  EXPECT_EQ(server.stop(), 0);
}

TEST(Server, SigtermSavesASnapshotAndARestartResumesTheIdenticalMap) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 2);
  ServerProcess server(dir.path(), 142);
  {
    auto client = connect(142);
    ASSERT_TRUE(client);
    replay(*client, raws);
  }
  EXPECT_EQ(server.stop(), 0);
  ASSERT_TRUE(std::filesystem::exists(dir.path() / "map.dmap"));
  server.start();
  auto client = connect(142);
  ASSERT_TRUE(client);
  auto fetched = client->fetchMap(raws.size());
  ASSERT_TRUE(fetched) << fetched.error().message;
  EXPECT_EQ(fetched->version(), raws.size());  // the version resumes too
  EXPECT_EQ(diffMaps(testing::gridOf(*fetched), *offlineMap(raws)).differing(), 0U);
  auto cleared = client->clearBox(Point3f(0, 0, 0), Point3f(5, 5, 2));
  ASSERT_TRUE(cleared) << cleared.error().message;
  EXPECT_NE(cleared->find("erased"), std::string::npos);
  auto reset = client->reset();
  ASSERT_TRUE(reset);
  auto empty = client->queryBox(Point3f(0, 0, 0), Point3f(30, 20, 3));
  ASSERT_TRUE(empty);
  EXPECT_EQ(empty->occupied + empty->free, 0U);
  EXPECT_EQ(server.stop(), 0);
}

TEST(Server, BadInputIsRejectedCountedAndLeavesTheMapUnchanged) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 1);
  ServerProcess server(dir.path(), 143,
                       "pipeline { max_points: 20000 max_abs_position_m: 500 queue_depth: 16 }\n");
  auto client = connect(143);
  ASSERT_TRUE(client);
  replay(*client, raws);
  const auto before = client->fetchMap(1);
  ASSERT_TRUE(before);

  std::vector<RawScan> bad(7, raws[0]);
  bad[0].xyz[1] = std::numeric_limits<float>::quiet_NaN();
  bad[1].xyz[5] = -std::numeric_limits<float>::infinity();
  bad[2].xyz.pop_back();
  bad[3].xyz.resize(3 * 20001, 1.0F);
  bad[4].q_world_sensor = {2, 0, 0, 0};
  bad[5].t_world_sensor = {0, 9000, 0};
  bad[6].xyz.clear();
  for (std::size_t i = 0; i < bad.size(); ++i) {
    bad[i].seq = 100 + i;
    ASSERT_TRUE(client->publishScan(bad[i]));
    std::this_thread::sleep_for(20ms);
  }
  // Bad queries and commands get an error reply.
  auto inverted = client->queryBox(Point3f(1, 1, 1), Point3f(0, 0, 0));
  ASSERT_FALSE(inverted);
  EXPECT_NE(inverted.error().message.find("inverted"), std::string::npos);
  EXPECT_FALSE(client->queryBox(Point3f(-1000, -1000, -100), Point3f(1000, 1000, 100)));
  EXPECT_FALSE(testing::queryPointsRaw(*client, {1.0F, 2.0F}));
  EXPECT_FALSE(client->castRay(Point3f(0, 0, 0), Point3f(0, 0, 0), 5.0F));
  EXPECT_FALSE(client->clearBox(Point3f(1, 1, 1), Point3f(0, 0, 0)));

  std::optional<ServerStatus> status;
  for (int i = 0; i < 50; ++i) {
    std::this_thread::sleep_for(100ms);
    auto s = client->status();
    if (s && s->rejected == bad.size() && s->queries_rejected >= 5) {
      status = *s;
      break;
    }
  }
  ASSERT_TRUE(status) << "status never showed every rejection";
  ASSERT_EQ(status->rejected_by_reason.size(), kRejectReasonCount);
  auto count = [&](RejectReason r) { return status->rejected_by_reason[static_cast<int>(r)]; };
  EXPECT_EQ(count(RejectReason::kNonFinitePoint), 2U);
  EXPECT_EQ(count(RejectReason::kLengthNotMultipleOf3), 1U);
  EXPECT_EQ(count(RejectReason::kTooManyPoints), 1U);
  EXPECT_EQ(count(RejectReason::kBadQuaternion), 1U);
  EXPECT_EQ(count(RejectReason::kPoseOutOfBounds), 1U);
  EXPECT_EQ(count(RejectReason::kEmpty), 1U);
  EXPECT_EQ(status->integrated, 1U);
  // Per sensor: the good scan (seq 1) and the bad ones (seq 100..106) of sensor "test".
  ASSERT_EQ(status->sensors.size(), 1U);
  EXPECT_EQ(status->sensors[0].sensor_id, "test");
  EXPECT_EQ(status->sensors[0].received, 1 + bad.size());
  EXPECT_EQ(status->sensors[0].integrated, 1U);
  EXPECT_EQ(status->sensors[0].rejected, bad.size());
  EXPECT_EQ(status->sensors[0].seq_gaps, 98U);
  EXPECT_EQ(status->map_version, 1U);
  auto after = client->fetchMap();
  ASSERT_TRUE(after);
  EXPECT_EQ(diffMaps(testing::gridOf(*after), testing::gridOf(*before)).differing(), 0U);
  EXPECT_EQ(server.stop(), 0);
}

TEST(Server, OverloadDropsScansKeepsLatencyBoundedAndMemoryFlat) {
  test::TempDir dir;
  auto raws = simulatedScans(dir.path(), 3);
  ServerProcess server(dir.path(), 144, "pipeline { threads: 1 queue_depth: 2 }\n");
  auto client = connect(144);
  ASSERT_TRUE(client);
  auto burst = [&](int first, int count) -> std::optional<ServerStatus> {
    for (int i = first; i < first + count; ++i) {
      RawScan raw = raws[i % raws.size()];
      raw.seq = i + 1;
      EXPECT_TRUE(client->publishScan(raw));
    }
    // Scans may also be overwritten in the DDS reader's keep-last history before the ingest
    // thread takes them (not counted as received). Wait until the server is idle: everything
    // it received is integrated or dropped, and nothing new arrived for a status period.
    std::uint64_t last_received = 0;
    for (int i = 0; i < 100; ++i) {
      std::this_thread::sleep_for(300ms);
      auto s = client->status();
      if (s && s->received == last_received && s->received > 0 &&
          s->integrated + s->dropped == s->received) {
        return *s;
      }
      if (s) last_received = s->received;
    }
    return std::nullopt;
  };
  // The same three scans over and over: the map stops growing, so memory must too.
  const auto first = burst(0, 60);
  ASSERT_TRUE(first) << "the server did not account for every scan";
  const long rss_first = server.residentKb();
  const auto second = burst(60, 120);
  ASSERT_TRUE(second) << "the server did not account for every scan";
  const long rss_second = server.residentKb();
  EXPECT_GT(second->dropped, 0U);
  EXPECT_GT(second->integrated, 0U);
  // A queue of 2 bounds how long a scan can wait: about two integrations, far below a second.
  EXPECT_LT(second->latency_p99_ms, 1000.0);
  EXPECT_GT(rss_first, 0);
  EXPECT_LT(rss_second - rss_first, 32 * 1024)
      << "resident memory grew from " << rss_first << " kB to " << rss_second << " kB";
  EXPECT_EQ(server.stop(), 0);
}

// A client may not name where the server writes. Before, `save
// --path FILE` replaced any file the server's user could write (a root-only 0600 file became a
// world-readable .dmap).
TEST(Server, SaveWritesOnlyPlainFileNamesIntoTheExportDirectory) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 1);
  ServerProcess server(dir.path(), 146);
  auto client = connect(146);
  ASSERT_TRUE(client);
  replay(*client, raws);
  const auto secret = dir.path() / "secret";
  std::ofstream(secret) << "root only";
  std::filesystem::permissions(
      secret, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  for (const std::string& hostile : std::vector<std::string>{
           secret.string(), "../secret", "exports/../../secret", "..", ".hidden.dmap", "map.dmap.1",
           "name with spaces.dmap", "x.txt", std::string(200, 'a') + ".dmap"}) {
    SCOPED_TRACE(hostile);
    auto saved = client->save(hostile);
    EXPECT_FALSE(saved);
  }
  std::ifstream in(secret);
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(content, "root only");
  // A plain name goes to exports/ beside the snapshot, and is the map.
  auto saved = client->save("copy.dmap");
  ASSERT_TRUE(saved) << saved.error().message;
  const auto exported = dir.path() / "exports" / "copy.dmap";
  EXPECT_NE(saved->find(exported.string()), std::string::npos) << *saved;
  auto loaded = loadSnapshot(exported, Backend::kGrid, 0.2);
  ASSERT_TRUE(loaded) << loaded.error().message;
  auto fetched = client->fetchMap();
  ASSERT_TRUE(fetched);
  EXPECT_EQ(diffMaps(*loaded->map, testing::gridOf(*fetched)).differing(), 0U);
  // A link planted under the name is replaced, never followed.
  const auto target = dir.path() / "target";
  std::ofstream(target) << "keep";
  std::filesystem::remove(exported);
  std::filesystem::create_symlink(target, exported);
  ASSERT_TRUE(client->save("copy.dmap"));
  EXPECT_FALSE(std::filesystem::is_symlink(exported));
  std::ifstream kept(target);
  std::string kept_content((std::istreambuf_iterator<char>(kept)),
                           std::istreambuf_iterator<char>());
  EXPECT_EQ(kept_content, "keep");
  EXPECT_EQ(server.stop(), 0);
}

// A snapshot resumed under another sensor model would apply the
// new model to new scans only (and record it in the next snapshot): refused with the reason.
TEST(Server, ASnapshotIsNotResumedUnderAnotherSensorModel) {
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 1);
  {
    ServerProcess server(dir.path(), 147);
    auto client = connect(147);
    ASSERT_TRUE(client);
    replay(*client, raws);
    ASSERT_EQ(server.stop(), 0);  // SIGTERM saves map.dmap with the default model
  }
  ASSERT_TRUE(std::filesystem::exists(dir.path() / "map.dmap"));
  const auto check = [&](const std::string& sensor) {
    const auto config = dir.path() / "check.textproto";
    std::ofstream(config) << "map { resolution_m: 0.2 max_range_m: 25 " << sensor << " }\n"
                          << "snapshot { path: \"" << (dir.path() / "map.dmap").string()
                          << "\" }\n";
    const std::string command = std::string(DENSEMAP_SERVER_BIN) + " --check-config " +
                                config.string() + " > " + (dir.path() / "out.txt").string() +
                                " 2>&1";
    const int status = std::system(command.c_str());
    std::ifstream in(dir.path() / "out.txt");
    std::string out((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return std::make_pair(WIFEXITED(status) ? WEXITSTATUS(status) : -1, out);
  };
  const auto same = check("");
  EXPECT_EQ(same.first, 0) << same.second;
  const auto other = check("sensor { prob_hit: 0.9 }");
  EXPECT_EQ(other.first, 2) << other.second;
  EXPECT_NE(other.second.find("prob_hit: 0.7"), std::string::npos) << other.second;
  EXPECT_NE(other.second.find("prob_hit: 0.9"), std::string::npos) << other.second;
}

// A snapshot directory that stops working loses no map. Failed
// saves show in the status (not as refused queries), and at SIGTERM a rescue copy is written.
TEST(Server, ASnapshotDirectoryThatDisappearsLosesNoMap) {
  test::TempDir top;
  const auto raws = simulatedScans(top.path(), 1);
  const auto dir = top.path() / "state";
  std::filesystem::create_directories(dir);
  ServerProcess server(dir, 148, "", false, /*autosave_s=*/0.05);
  auto client = connect(148);
  ASSERT_TRUE(client);
  std::filesystem::remove_all(dir);  // the disk goes away under the daemon
  replay(*client, raws);
  std::optional<ServerStatus> status;
  for (int i = 0; i < 50 && !status; ++i) {
    std::this_thread::sleep_for(100ms);
    if (auto s = client->status(); s && s->snapshot_failures > 0) status = *s;
  }
  ASSERT_TRUE(status) << "failed autosaves never showed in the status";
  EXPECT_NE(status->last_snapshot_error.find("map.dmap"), std::string::npos);
  EXPECT_EQ(status->queries_rejected, 0U);  // a failed save is not a refused request
  auto fetched = client->fetchMap();
  ASSERT_TRUE(fetched);
  const pid_t pid = server.pid();
  EXPECT_EQ(server.stop(), 1);  // the configured save failed ...
  // ... but the map is in the rescue copy (the export directory, recreated).
  const auto rescue = dir / "exports" / ("densemap-rescue-" + std::to_string(pid) + ".dmap");
  auto loaded = loadSnapshot(rescue, Backend::kGrid, 0.2);
  ASSERT_TRUE(loaded) << loaded.error().message;
  EXPECT_EQ(diffMaps(*loaded->map, testing::gridOf(*fetched)).differing(), 0U);
}

// Two servers on one domain flipped clients between two maps.
// The second refuses to start (exit 2, the reason); the first keeps its map and answers.
TEST(Server, ASecondServerOnTheSameDomainRefusesToStart) {
  test::TempDir first_dir, second_dir;
  const auto raws = simulatedScans(first_dir.path(), 1);
  ServerProcess first(first_dir.path(), 149);
  auto client = connect(149);
  ASSERT_TRUE(client);
  replay(*client, raws);
  ServerProcess second(second_dir.path(), 149, "", /*capture_log=*/true);
  for (int i = 0; i < 100 && kill(second.pid(), 0) == 0; ++i) {
    int status = 0;
    if (waitpid(second.pid(), &status, WNOHANG) == second.pid()) {
      EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2);
      break;
    }
    std::this_thread::sleep_for(50ms);
  }
  EXPECT_NE(second.log().find("another densemap-server"), std::string::npos) << second.log();
  std::uint64_t integrated = 0;  // the first server's status (1 Hz) still counts its scan
  for (int i = 0; i < 40 && integrated == 0; ++i) {
    if (auto s = client->status(); s) integrated = s->integrated;
    std::this_thread::sleep_for(100ms);
  }
  EXPECT_EQ(integrated, 1U);
  EXPECT_TRUE(client->queryPoints({Point3f(1, 1, 1)}));
  EXPECT_EQ(first.stop(), 0);
}

// Query requests in flight share one memory budget. One request
// carries at most dds::kMaxQueryPoints points, less than the smallest budget (16 MiB), so a
// large batch goes in parts that wait for the budget, and every point is answered.
TEST(Server, PointBatchesLargerThanTheRequestBudgetAreAnsweredInParts) {
  test::TempDir dir;
  ServerProcess server(dir.path(), 150, "pipeline { request_budget_mb: 16 }\n");
  auto client = connect(150);
  ASSERT_TRUE(client);
  std::vector<Point3f> many(4 * std::size_t{dds::kMaxQueryPoints}, Point3f(1, 1, 1));
  auto answered = client->queryPoints(many);  // ~88 MiB in all
  ASSERT_TRUE(answered) << answered.error().message;
  EXPECT_EQ(answered->states.size(), many.size());
  EXPECT_EQ(server.stop(), 0);
}

// Clients flooding the server with large point batches (sent in parts of
// dds::kMaxQueryPoints): the server's RSS stays under its request budget + 64 MiB above where it
// started (the map is empty), and within 10 s of the flood it has handed back most of what the
// flood took (the heap trimmed once no request is in flight). Before: 8
// clients x 10M points took it from 90 MB to 1.8 GB, and 159 MB stayed.
TEST(Server, APointQueryFloodStaysInTheRequestBudgetAndItsMemoryReturns) {
  test::TempDir dir;
  ServerProcess server(dir.path(), 152);  // the default request budget, 256 MiB
  std::vector<std::unique_ptr<Client>> clients;
  for (int c = 0; c < 6; ++c) {
    clients.push_back(connect(152));
    ASSERT_TRUE(clients.back());
  }
  const long start_kb = server.residentKb();
  std::atomic<bool> done{false};
  long peak_kb = start_kb;
  std::thread sampler([&] {
    while (!done.load()) {
      peak_kb = std::max(peak_kb, server.residentKb());
      std::this_thread::sleep_for(20ms);
    }
  });
  std::vector<std::thread> floods;
  std::atomic<int> answered{0};
  for (auto& client : clients) {
    floods.emplace_back([&client, &answered] {
      std::vector<float> xyz(3 * 3'000'000, 1.0F);
      if (auto a = testing::queryPointsRaw(*client, xyz); a && a->states.size() == 3'000'000)
        ++answered;
    });
  }
  for (auto& t : floods) t.join();
  done = true;
  sampler.join();
  EXPECT_EQ(answered.load(), 6);
  EXPECT_LT(peak_kb - start_kb, (256 + 64) * 1024) << "start " << start_kb << " kB";
  clients.clear();
  long after_kb = 0;
  for (int i = 0; i < 100; ++i) {
    after_kb = server.residentKb();
    if (4 * (after_kb - start_kb) < peak_kb - start_kb) break;
    std::this_thread::sleep_for(100ms);
  }
  // Runs kept 6-37% of what the flood took; without the heap trims all of it stayed.
  std::cerr << "flood: start " << start_kb << " kB, peak " << peak_kb << " kB, after " << after_kb
            << " kB\n";
  EXPECT_LT(4 * (after_kb - start_kb), 3 * (peak_kb - start_kb))
      << "start " << start_kb << " kB, peak " << peak_kb << " kB, 10 s after " << after_kb;
  EXPECT_EQ(server.stop(), 0);
}

// A reply reaches its asker only (every client read every reply: 30 clients'
// 2.7 MB bbox replies took 6.7 s against 0.28 s for one). Another client's reply readers, and
// a reader in the default partition, receive nothing of a client's answers.
TEST(Server, RepliesReachTheAskerOnly) {
  test::TempDir dir;
  ServerProcess server(dir.path(), 153);
  auto asker = connect(153);
  ASSERT_TRUE(asker);
  auto participant = dds::createParticipant({153, "lo", std::nullopt});
  ASSERT_TRUE(participant) << participant.error().message;
  auto topics = dds::Topics::create(*participant);
  ASSERT_TRUE(topics);
  const std::string other = dds::replyPartition(12345);
  dds::QosSpec other_qos = dds::kRequestQos;
  other_qos.partition = other;
  auto default_reader = dds::createReader(*participant, topics->point_reply, dds::kRequestQos);
  auto other_reader = dds::createReader(*participant, topics->point_reply, other_qos);
  auto box_reader = dds::createReader(*participant, topics->bbox_reply, other_qos);
  ASSERT_TRUE(default_reader && other_reader && box_reader);
  std::this_thread::sleep_for(300ms);  // discovered by the server before the asker asks
  for (int i = 0; i < 5; ++i) {
    auto points = asker->queryPoints({Point3f(1, 1, 1), Point3f(2, 2, 2)});
    ASSERT_TRUE(points) << points.error().message;
    EXPECT_EQ(points->states.size(), 2U);
    ASSERT_TRUE(asker->queryBox({-1, -1, -1}, {1, 1, 1}));
  }
  std::this_thread::sleep_for(300ms);
  int seen = 0;
  for (const dds::Entity* r : {&*default_reader, &*other_reader}) {
    dds::takeAll<densemap_msgs_PointQueryReply>(*r, [&](const auto&) { ++seen; });
  }
  dds::takeAll<densemap_msgs_BboxQueryReply>(*box_reader, [&](const auto&) { ++seen; });
  EXPECT_EQ(seen, 0);
  // A second client gets its own answers as well.
  auto second = connect(153);
  ASSERT_TRUE(second);
  auto answer = second->queryPoints({Point3f(1, 1, 1)});
  ASSERT_TRUE(answer) << answer.error().message;
  EXPECT_EQ(server.stop(), 0);
}

// One request carries at most dds::kMaxQueryPoints points (the server refuses
// more, whatever its budget); the client library sends a larger batch in parts, one after
// another, and answers every point in order.
TEST(Server, PointBatchesOverTheRequestLimitAreSplitByTheClientAndRefusedWhole) {
  test::TempDir dir;
  ServerProcess server(dir.path(), 151, "pipeline { request_budget_mb: 1024 }\n");
  auto client = connect(151);
  ASSERT_TRUE(client);
  (void)replay(*client, simulatedScans(dir.path(), 1));
  // Points on a plane through the scan: a pattern of free, occupied and unknown cells.
  const std::size_t n = 2 * std::size_t{dds::kMaxQueryPoints} + 12345;
  std::vector<float> xyz(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    xyz[3 * i] = 0.1F * static_cast<float>(i % 200) - 10.0F;
    xyz[3 * i + 1] = 0.5F * static_cast<float>((i / 200) % 40) - 10.0F;
    xyz[3 * i + 2] = 0.2F;
  }
  auto whole = testing::queryPointsRaw(*client, xyz);
  ASSERT_TRUE(whole) << whole.error().message;
  ASSERT_EQ(whole->states.size(), n);
  ASSERT_EQ(whole->log_odds.size(), n);
  // Each point's answer is the one a small request for it gets (8,000 points repeat with
  // period 8,000, so compare every part against the first 8,000).
  std::vector<float> first(xyz.begin(), xyz.begin() + 3 * 8000);
  auto small = testing::queryPointsRaw(*client, first);
  ASSERT_TRUE(small) << small.error().message;
  std::size_t occupied = 0;
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(whole->states[i], small->states[i % 8000]) << i;
    ASSERT_EQ(whole->log_odds[i], small->log_odds[i % 8000]) << i;
    occupied += whole->states[i] == CellState::kOccupied;
  }
  EXPECT_GT(occupied, 0U);
  // One request over the limit is refused with the reason.
  std::vector<float> over(3 * (std::size_t{dds::kMaxQueryPoints} + 1), 1.0F);
  auto refused = testing::queryPointsOnce(*client, over);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("at most " + std::to_string(dds::kMaxQueryPoints)),
            std::string::npos)
      << refused.error().message;
  EXPECT_EQ(server.stop(), 0);
}

}  // namespace
}  // namespace densemap
