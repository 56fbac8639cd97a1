// densemap-server's ROS 2 face end to end, as separate processes on loopback (one DDS domain
// per test): `densemap replay --ros` publishes simulated scans as PointCloud2 + TF with clouds
// stamped between TF samples; the server's map equals the offline map of the same clouds at
// the interpolated poses, cell for cell; its octomap_binary, projected_map and occupied-centre
// messages equal the map; malformed clouds are counted by reason and the server stays up.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cstring>
#include <future>
#include <map>
#include <sstream>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/planner/distance_slice.hpp"
#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/names.hpp"
#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/ros2/replay_frames.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/server_config.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/topics.hpp"
#include "nav_msgs.h"
#include "octomap_msgs.h"
#include "rmw_dds_common.h"
#include "sensor_msgs.h"
#include "tf2_msgs.h"

namespace densemap {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

constexpr std::int64_t kStampBase = 1'700'000'000'000'000'000;
constexpr double kRate = 10.0;

const char* kRosConfig =
    "ros2 { enabled: true reliable_clouds: true world_frame: \"map\" tf_wait_s: 3\n"
    "       max_waiting_clouds: 20 publish_period_s: 0.2 grid_min_z_m: -0.5 grid_max_z_m: 1.5\n"
    "       esdf_slice_z_m: 1.1 robot_radius_m: 0.45 }\n"
    "esdf { enabled: true max_distance_m: 1.0 }\n";

std::unique_ptr<Client> connect(std::uint32_t domain) { return test::connectClient(domain); }

int runCli(const std::string& args) {
  const std::string command = std::string(DENSEMAP_CLI_BIN) + " " + args + " >/dev/null 2>&1";
  return std::system(command.c_str());
}

#ifndef DENSEMAP_ROS2_REALDATA
/// `scans` simulated VLP-16 scans (300 columns) of the indoor scene in `dir`.
bool writeSmallIndoorScans(const fs::path& dir, int scans) {
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 300;
  o.scans = scans;
  o.ground_truth_resolution_m = 0;
  return static_cast<bool>(writeSimulatedSequence(o, dir));
}
#endif

/// Waits until the server's status satisfies `done`; returns the last status.
ServerStatus waitForStatus(Client& client, const std::function<bool(const ServerStatus&)>& done) {
  ServerStatus last;
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  while (std::chrono::steady_clock::now() < deadline) {
    if (auto s = client.status(); s) {
      last = *s;
      if (done(last)) break;
    }
    std::this_thread::sleep_for(100ms);
  }
  return last;
}

/// Scans [first, first + count) of `data` as the server gets them from `densemap replay --ros
/// --first FIRST`: posed as a TF buffer fed the replay's transforms gives at the clouds'
/// stamps, numbered 1, 2 ... as the server numbers a topic's clouds.
std::vector<RawScan> rosScans(const fs::path& data, std::size_t first, std::size_t count,
                              const ros2::ReplayFrames& frames, const std::string& sensor_id) {
  auto source = openScanSource(data);
  EXPECT_TRUE(source);
  std::vector<RawScan> raws;
  for (std::size_t i = first; i < std::min(first + count, (*source)->size()); ++i) {
    raws.push_back(toRawScan(*(*source)->load(i), raws.size() + 1, sensor_id));
  }
  ros2::TfBuffer tf;
  EXPECT_TRUE(tf.set(frames.map, frames.odom,
                     {frames.stampOf(0), Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity()},
                     true));
  EXPECT_TRUE(tf.set(frames.base, frames.sensor, ros2::sensorMount(), true));
  for (std::size_t k = 0; k <= raws.size(); ++k) {
    const RawScan& r = raws[std::min(k, raws.size() - 1)];
    EXPECT_TRUE(tf.set(
        frames.odom, frames.base,
        ros2::odomToBase(ros2::fromScanPose(r.t_world_sensor, r.q_world_sensor), frames.stampOf(k)),
        false));
  }
  for (std::size_t k = 0; k < raws.size(); ++k) {
    auto T = tf.lookup(frames.map, frames.sensor, frames.cloudStamp(k));
    EXPECT_TRUE(T);
    const ros2::ScanPose pose = ros2::toScanPose(*T);
    raws[k].t_world_sensor = pose.t;
    raws[k].q_world_sensor = pose.q;
  }
  return raws;
}

/// The map of `raws` integrated in order, one at a time, through a pipeline with the options of
/// the server configured by `config`.
std::shared_ptr<const MapView> offlineMap(const std::vector<RawScan>& raws,
                                          const fs::path& config) {
  auto cfg = server::loadServerConfig(config);
  EXPECT_TRUE(cfg) << cfg.error().message;
  auto options = server::ingestOptions(*cfg);
  EXPECT_TRUE(options);
  auto pipeline = server::Ingest::create(*options);
  EXPECT_TRUE(pipeline);
  (*pipeline)->start();
  for (std::size_t k = 0; k < raws.size(); ++k) {
    (*pipeline)->submit(RawScan(raws[k]));
    for (int i = 0; i < 3000 && (*pipeline)->counters().integrated <= k; ++i) {
      std::this_thread::sleep_for(1ms);
    }
  }
  (*pipeline)->stop();
  return (*pipeline)->view();
}

/// The map the server must hold: the same clouds, at the poses the replay's transforms give,
/// through a pipeline with the server's options.
std::shared_ptr<const MapView> expectedMap(const fs::path& data, std::size_t scans,
                                           const fs::path& config,
                                           const ros2::ReplayFrames& frames) {
  return offlineMap(rosScans(data, 0, scans, frames, "/points"), config);
}

/// Whether `map` holds exactly `expected`'s cells and values.
void expectSameMap(const GridMap& map, const MapView& expected) {
  GridMap expected_map(map.resolution(), map.sensorModel());
  expected.forEachKnown([&](const VoxelKey& k, float v) { expected_map.setLogOdds(k, v); });
  const MapDiff diff = diffMaps(map, expected_map);
  EXPECT_EQ(diff.differing(), 0U) << diff.only_in_a << " / " << diff.only_in_b << " / "
                                  << diff.value_mismatch << " of " << diff.union_cells;
}

/// The latest sample of a transient-local ROS topic, copied out by `copy`.
template <class T>
bool latestSample(const dds::Entity& reader, const std::function<void(const T&)>& copy) {
  bool got = false;
  dds::forEachSample<T>(reader, false, [&](const T& m) {
    copy(m);
    got = true;
  });
  return got;
}

/// Replays `scans` scans of `data` through the ROS path into a server on `domain` and checks
/// the map and the map topics.
void replayAndCompare(const fs::path& data, std::size_t scans, std::uint32_t kDomain,
                      const fs::path& dir) {
  test::ServerProcess server(dir, kDomain, kRosConfig);
  auto client = connect(kDomain);
  ASSERT_TRUE(client);

  // A ROS tool's readers of the map topics (transient-local: they get the latest on joining).
  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto octomap_topic = dds::createTopic(*participant, octomap_msgs_msg_dds__Octomap__desc,
                                        ros2::ddsTopicName("/octomap_binary"));
  auto grid_topic = dds::createTopic(*participant, nav_msgs_msg_dds__OccupancyGrid__desc,
                                     ros2::ddsTopicName("/projected_map"));
  auto centers_topic = dds::createTopic(*participant, sensor_msgs_msg_dds__PointCloud2__desc,
                                        ros2::ddsTopicName("/octomap_point_cloud_centers"));
  ASSERT_TRUE(octomap_topic && grid_topic && centers_topic);
  const dds::QosSpec latched{.depth = 1, .transient_local = true};
  auto octomap_reader = dds::createReader(*participant, *octomap_topic, latched);
  auto grid_reader = dds::createReader(*participant, *grid_topic, latched);
  auto centers_reader = dds::createReader(*participant, *centers_topic, latched);
  ASSERT_TRUE(octomap_reader && grid_reader && centers_reader);
  auto slice_topic = dds::createTopic(*participant, sensor_msgs_msg_dds__PointCloud2__desc,
                                      ros2::ddsTopicName("/esdf_slice"));
  auto costmap_topic = dds::createTopic(*participant, nav_msgs_msg_dds__OccupancyGrid__desc,
                                        ros2::ddsTopicName("/costmap"));
  ASSERT_TRUE(slice_topic && costmap_topic);
  auto slice_reader = dds::createReader(*participant, *slice_topic, latched);
  auto costmap_reader = dds::createReader(*participant, *costmap_topic, latched);
  ASSERT_TRUE(slice_reader && costmap_reader);

  ros2::ReplayFrames frames;
  frames.stamp_base_ns = kStampBase;
  frames.period_ns = static_cast<std::int64_t>(1e9 / kRate);
  frames.stamp_offset = 0.5;  // between two TF samples: interpolated, and waits for the next
  ASSERT_EQ(
      runCli("--domain-id " + std::to_string(kDomain) + " replay --ros --data " + data.string() +
             " --limit " + std::to_string(scans) +
             " --rate 10 --ros-stamp-offset 0.5 --ros-stamp-base-ns " + std::to_string(kStampBase)),
      0);
  const ServerStatus status =
      waitForStatus(*client, [&](const ServerStatus& s) { return s.integrated >= scans; });
  EXPECT_TRUE(status.ros_enabled);
  EXPECT_EQ(status.ros_received, scans);
  EXPECT_EQ(status.ros_submitted, scans);
  EXPECT_EQ(status.integrated, scans);
  EXPECT_EQ(status.ros_no_transform, 0U);

  auto fetched = client->fetchMap(scans);
  ASSERT_TRUE(fetched) << fetched.error().message;
  const GridMap& map = testing::gridOf(*fetched);
  const auto expected = expectedMap(data, scans, dir / "server.textproto", frames);
  ASSERT_GT(map.knownCells(), 10000U);
  expectSameMap(map, *expected);

  // The map topics, once they carry the final map (published at most every 0.2 s).
  const auto view = MapView::fromMap(map, scans);
  std::size_t occupied = 0;
  map.forEachKnown([&](const VoxelKey&, float v) { occupied += SensorModel::isOccupied(v); });
  std::string octomap_data, octomap_id;
  double octomap_resolution = 0;
  bool octomap_binary = false;
  ros2::GridImage grid;
  std::size_t centers = 0;
  std::string frame_id;
  const auto deadline = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < deadline) {
    latestSample<octomap_msgs_msg_dds__Octomap_>(*octomap_reader, [&](const auto& m) {
      octomap_data.assign(reinterpret_cast<const char*>(m.data._buffer), m.data._length);
      octomap_id = m.id;
      octomap_resolution = m.resolution;
      octomap_binary = m.binary;
      frame_id = m.header.frame_id;
    });
    latestSample<nav_msgs_msg_dds__OccupancyGrid_>(*grid_reader, [&](const auto& m) {
      grid.width = m.info.width;
      grid.height = m.info.height;
      grid.origin_x = m.info.origin.position.x;
      grid.origin_y = m.info.origin.position.y;
      grid.resolution = m.info.resolution;
      grid.data.assign(m.data._buffer, m.data._buffer + m.data._length);
    });
    latestSample<sensor_msgs_msg_dds__PointCloud2_>(*centers_reader,
                                                    [&](const auto& m) { centers = m.width; });
    if (centers == occupied) break;
    std::this_thread::sleep_for(100ms);
  }
  EXPECT_EQ(centers, occupied);
  EXPECT_EQ(octomap_id, "OcTree");
  EXPECT_TRUE(octomap_binary);
  EXPECT_EQ(octomap_resolution, 0.2);
  EXPECT_EQ(frame_id, "map");
  octomap::OcTree tree(0.2);
  std::istringstream in(octomap_data);
  ASSERT_TRUE(tree.readBinaryData(in));
  std::size_t cells = 0, agree = 0;
  map.forEachKnown([&](const VoxelKey& k, float v) {
    ++cells;
    const octomap::OcTreeNode* n = tree.search(octomap::OcTreeKey(k.x, k.y, k.z));
    if (n != nullptr && tree.isNodeOccupied(n) == SensorModel::isOccupied(v)) ++agree;
  });
  EXPECT_EQ(agree, cells);
  tree.expand();
  EXPECT_EQ(tree.getNumLeafNodes(), cells);
  const ros2::GridImage reference = ros2::MapTopicsState::project(*view, -0.5, 1.5);
  EXPECT_EQ(grid.width, reference.width);
  EXPECT_EQ(grid.height, reference.height);
  EXPECT_EQ(grid.origin_x, reference.origin_x);
  EXPECT_EQ(grid.origin_y, reference.origin_y);
  EXPECT_FLOAT_EQ(static_cast<float>(grid.resolution), 0.2F);
  EXPECT_EQ(grid.data, reference.data);

  // The distance field's layer and costmap: those of a field built from the same map.
  auto field = DistanceField::create(0.2, {.max_distance_m = 1.0});
  ASSERT_TRUE(field);
  field->rebuild(*view);
  const auto want_slice = distanceSlice(*field, 1.1);
  const Costmap want_costmap = inflatedCostmap(*field, *view, 1.1, 0.45);
  std::vector<std::array<float, 4>> slice;
  std::vector<std::string> slice_fields;
  Costmap costmap;
  const auto field_deadline = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < field_deadline) {
    latestSample<sensor_msgs_msg_dds__PointCloud2_>(*slice_reader, [&](const auto& m) {
      slice.resize(m.width);
      if (m.point_step == 16 && m.data._length == 16 * m.width && m.width > 0) {
        std::memcpy(slice.data(), m.data._buffer, m.data._length);
      }
      slice_fields.clear();
      for (std::uint32_t i = 0; i < m.fields._length; ++i) {
        slice_fields.emplace_back(m.fields._buffer[i].name);
      }
    });
    latestSample<nav_msgs_msg_dds__OccupancyGrid_>(*costmap_reader, [&](const auto& m) {
      costmap.width = m.info.width;
      costmap.height = m.info.height;
      costmap.origin_x = m.info.origin.position.x;
      costmap.origin_y = m.info.origin.position.y;
      costmap.data.assign(m.data._buffer, m.data._buffer + m.data._length);
    });
    if (slice.size() == want_slice.size() && costmap.data == want_costmap.data) break;
    std::this_thread::sleep_for(100ms);
  }
  ASSERT_GT(want_slice.size(), 100U);
  EXPECT_EQ(slice_fields, (std::vector<std::string>{"x", "y", "z", "distance"}));
  auto sorted = [](std::vector<std::array<float, 4>> v) {
    std::sort(v.begin(), v.end());
    return v;
  };
  EXPECT_EQ(sorted(slice), sorted(want_slice));
  EXPECT_EQ(costmap.width, want_costmap.width);
  EXPECT_EQ(costmap.origin_x, want_costmap.origin_x);
  EXPECT_EQ(costmap.origin_y, want_costmap.origin_y);
  EXPECT_EQ(costmap.data, want_costmap.data);
  EXPECT_GT(std::count(costmap.data.begin(), costmap.data.end(), 100), 10);
  EXPECT_EQ(server.stop(), 0);
}

#ifndef DENSEMAP_ROS2_REALDATA
TEST(Ros2Wire, ReplayedPointCloud2AndTfGiveTheOfflineMapAndTheMapTopicsAgree) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 600;
  o.scans = 6;
  o.ground_truth_resolution_m = 0;
  ASSERT_TRUE(writeSimulatedSequence(o, dir.path() / "data"));
  replayAndCompare(dir.path() / "data", 6, 167, dir.path());
}
#else
TEST(Ros2Wire, RealScansThroughPointCloud2AndTfGiveTheOfflineMap) {
  DENSEMAP_REQUIRE_DATA(balm, "balm-realworld");
  test::TempDir dir;
  replayAndCompare(balm, 5, 168, dir.path());
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
/// A robot of a fleet test: a ROS 2 namespace ("/robot1") or a native sensor id.
struct FleetRobot {
  std::string name;
  bool ros = true;
  [[nodiscard]] std::string sensorId() const { return ros ? name + "/points" : name; }
};

/// Replays `per_robot` scans for each robot, all at once, each robot its own stretch of one
/// simulated path, into a server on `domain` with `ros2_config`. Checks that the map equals the
/// offline map of all their scans in the order the server integrated them (its map events say
/// which scan each version was), cell for cell, and that status counts each robot's sensor
/// apart, with its latency.
void replayFleetAndCompare(std::uint32_t domain, const std::string& ros2_config,
                           const std::vector<FleetRobot>& fleet, std::size_t per_robot) {
  test::TempDir dir;
  const fs::path data = dir.path() / "data";
  const std::size_t n = fleet.size() * per_robot;
  ASSERT_TRUE(writeSmallIndoorScans(data, static_cast<int>(n)));
  test::ServerProcess server(dir.path(), domain, ros2_config);
  auto client = connect(domain);
  ASSERT_TRUE(client);

  ros2::ReplayFrames frames;
  frames.stamp_base_ns = kStampBase;
  frames.stamp_offset = 0.5;
  const auto robotArgs = [&](std::size_t r) {
    const std::string common = "--domain-id " + std::to_string(domain) + " replay --data " +
                               data.string() + " --rate 10 --first " +
                               std::to_string(r * per_robot) + " --limit " +
                               std::to_string(per_robot);
    if (fleet[r].ros) {
      return common + " --ros --ros-namespace " + fleet[r].name +
             " --ros-stamp-offset 0.5 --ros-stamp-base-ns " + std::to_string(kStampBase);
    }
    return common + " --sensor-id " + fleet[r].name;
  };
  std::vector<std::future<int>> robots;
  for (std::size_t r = 0; r < fleet.size(); ++r) {
    robots.push_back(std::async(std::launch::async, [&, r] { return runCli(robotArgs(r)); }));
  }
  // The order of integration, from the map events (the server keeps 64 for a slow reader).
  std::vector<std::pair<std::string, std::uint64_t>> order;
  const auto poll = [&] {
    client->pollEvents([&](const MapEventInfo& e) {
      if (e.from_scan) order.emplace_back(e.sensor_id, e.scan_seq);
    });
  };
  const auto deadline = std::chrono::steady_clock::now() + 60s;
  while (order.size() < n && std::chrono::steady_clock::now() < deadline) {
    poll();
    std::this_thread::sleep_for(50ms);
  }
  for (auto& r : robots) EXPECT_EQ(r.get(), 0);
  poll();
  ASSERT_EQ(order.size(), n);

  // Each robot's scans as the server got them: the ROS robots' at the poses of their own TF
  // trees, numbered per topic; the native robots' as sent (numbered by dataset index + 1).
  std::map<std::pair<std::string, std::uint64_t>, RawScan> sent;
  std::size_t ros_robots = 0;
  for (std::size_t r = 0; r < fleet.size(); ++r) {
    if (fleet[r].ros) {
      ++ros_robots;
      for (RawScan& raw : rosScans(data, r * per_robot, per_robot, frames, fleet[r].sensorId())) {
        sent.emplace(std::make_pair(raw.sensor_id, raw.seq), std::move(raw));
      }
      continue;
    }
    auto source = openScanSource(data);
    ASSERT_TRUE(source);
    for (std::size_t i = r * per_robot; i < (r + 1) * per_robot; ++i) {
      RawScan raw = toRawScan(*(*source)->load(i), i + 1, fleet[r].sensorId());
      sent.emplace(std::make_pair(raw.sensor_id, raw.seq), std::move(raw));
    }
  }
  std::vector<RawScan> arrival;
  for (const auto& key : order) {
    auto it = sent.find(key);
    ASSERT_NE(it, sent.end()) << key.first << " #" << key.second;
    arrival.push_back(it->second);
  }
  // The robots really were interleaved: not every robot's scans came in one run.
  std::size_t switches = 0;
  for (std::size_t i = 1; i < order.size(); ++i) switches += order[i].first != order[i - 1].first;
  EXPECT_GE(switches, fleet.size());

  auto fetched = client->fetchMap(order.size());
  ASSERT_TRUE(fetched) << fetched.error().message;
  const GridMap& map = testing::gridOf(*fetched);
  ASSERT_GT(map.knownCells(), 10000U);
  expectSameMap(map, *offlineMap(arrival, dir.path() / "server.textproto"));

  const ServerStatus status = waitForStatus(*client, [&](const ServerStatus& s) {
    return s.integrated == n && s.sensors.size() == fleet.size();
  });
  EXPECT_EQ(status.ros_submitted, ros_robots * per_robot);
  EXPECT_EQ(status.ros_no_transform, 0U);
  ASSERT_EQ(status.sensors.size(), fleet.size());
  for (const SensorCounters& c : status.sensors) {
    EXPECT_TRUE(std::any_of(fleet.begin(), fleet.end(), [&](const FleetRobot& r) {
      return r.sensorId() == c.sensor_id;
    })) << c.sensor_id;
    EXPECT_EQ(c.received, per_robot) << c.sensor_id;
    EXPECT_EQ(c.integrated, per_robot) << c.sensor_id;
    EXPECT_EQ(c.seq_gaps, 0U) << c.sensor_id;
    EXPECT_GT(c.latency_p50_ms, 0.0) << c.sensor_id;
    EXPECT_GE(c.latency_p99_ms, c.latency_p50_ms) << c.sensor_id;
  }
  EXPECT_EQ(server.stop(), 0);
}

// A fleet into one map: four robots along one scene's path, two as ROS 2 robots in their own
// namespaces (their own TF trees, every one with frames named odom and base_link) and two with
// native scans, all at once.
TEST(Ros2Wire, FourRobotsThroughNamespacesAndNativeScansGiveTheOfflineMapInArrivalOrder) {
  replayFleetAndCompare(
      201,
      "ros2 { enabled: true reliable_clouds: true tf_wait_s: 3 "
      "publish_period_s: 0 robots: \"/robot1\" robots: \"robot2\" }\n",
      {{"/robot1"}, {"/robot2"}, {"robot3/lidar", false}, {"robot4/lidar", false}}, 4);
}

// Robots found on the wire: no robot is listed, the namespace glob admits both when their
// publishers appear (each replay waits for the server's reader of its cloud topic).
TEST(Ros2Wire, RobotsWhoseNamespaceMatchesThePatternAreFoundWhenTheyAppear) {
  replayFleetAndCompare(205,
                        "ros2 { enabled: true reliable_clouds: true tf_wait_s: 3 "
                        "publish_period_s: 0 robot_pattern: \"/robot*\" }\n",
                        {{"/robot_a"}, {"/robot_b"}}, 4);
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
/// A PointCloud2 message from a layout and raw bytes.
struct RawCloud {
  std::vector<sensor_msgs_msg_dds__PointField_> fields;
  std::vector<std::string> names;
  std::vector<std::uint8_t> data;
  std::uint32_t width = 0, height = 1, point_step = 12, row_step = 0;
  bool big = false;
  std::string frame = "map";
};

RawCloud xyzCloud(std::uint32_t n, std::uint8_t type = 7) {
  RawCloud c;
  const std::uint32_t size = type == 8 ? 8 : 4;
  c.names = {"x", "y", "z"};
  for (std::uint32_t a = 0; a < 3; ++a) c.fields.push_back({nullptr, a * size, type, 1});
  c.width = n;
  c.point_step = 3 * size;
  c.row_step = n * c.point_step;
  c.data.resize(c.row_step);
  for (std::uint32_t i = 0; i < n; ++i) {
    for (std::uint32_t a = 0; a < 3; ++a) {
      const double v = a == 0 ? 2.0 + 0.01 * i : (a == 1 ? 0.02 * i : 0.5);
      if (type == 8) {
        std::memcpy(c.data.data() + i * c.point_step + a * 8, &v, 8);
      } else {
        const float f = static_cast<float>(v);
        std::memcpy(c.data.data() + i * c.point_step + a * 4, &f, 4);
      }
    }
  }
  return c;
}

void publish(const dds::Entity& writer, RawCloud c) {
  for (std::size_t i = 0; i < c.fields.size(); ++i) {
    c.fields[i].name = const_cast<char*>(c.names[i].c_str());
  }
  sensor_msgs_msg_dds__PointCloud2_ m{};
  m.header.stamp = {1, 0};
  m.header.frame_id = const_cast<char*>(c.frame.c_str());
  m.height = c.height;
  m.width = c.width;
  m.fields._length = m.fields._maximum = static_cast<std::uint32_t>(c.fields.size());
  m.fields._buffer = c.fields.data();
  m.is_bigendian = c.big;
  m.point_step = c.point_step;
  m.row_step = c.row_step;
  m.data._length = m.data._maximum = static_cast<std::uint32_t>(c.data.size());
  m.data._buffer = c.data.data();
  m.is_dense = true;
  ASSERT_TRUE(dds::write(writer, &m));
}

TEST(Ros2Wire, MalformedCloudsAreCountedByReasonAndTheServerKeepsMapping) {
  constexpr std::uint32_t kDomain = 188;
  test::TempDir dir;
  test::ServerProcess server(
      dir.path(), kDomain,
      // tf_wait_s: the valid clouds may wait for the static transform when a loaded machine
      // delivers it late (the test waits for the lost cloud's drop anyway).
      "ros2 { enabled: true reliable_clouds: true tf_wait_s: 2 publish_period_s: 0 }\n");
  auto client = connect(kDomain);
  ASSERT_TRUE(client);
  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto topic = dds::createTopic(*participant, sensor_msgs_msg_dds__PointCloud2__desc, "rt/points");
  ASSERT_TRUE(topic);
  auto writer = dds::createWriter(*participant, *topic, {.depth = 0});
  ASSERT_TRUE(writer);
  // A static map -> odom transform makes "map" a known frame: clouds in it need no motion.
  auto tf_topic = dds::createTopic(*participant, tf2_msgs_msg_dds__TFMessage__desc, "rt/tf_static");
  ASSERT_TRUE(tf_topic);
  auto tf_writer =
      dds::createWriter(*participant, *tf_topic, {.depth = 1, .transient_local = true});
  ASSERT_TRUE(tf_writer);
  geometry_msgs_msg_dds__TransformStamped_ ts{};
  ts.header.frame_id = const_cast<char*>("map");
  ts.child_frame_id = const_cast<char*>("odom");
  ts.transform.rotation.w = 1.0;
  tf2_msgs_msg_dds__TFMessage_ tf_msg{};
  tf_msg.transforms._length = tf_msg.transforms._maximum = 1;
  tf_msg.transforms._buffer = &ts;
  ASSERT_TRUE(dds::write(*tf_writer, &tf_msg));
  for (int i = 0; i < 100; ++i) {
    dds_publication_matched_status_t m{};
    if (dds_get_publication_matched_status(writer->get(), &m) >= 0 && m.current_count > 0) break;
    std::this_thread::sleep_for(20ms);
  }
  std::this_thread::sleep_for(300ms);  // the static transform reaches the server first

  using ros2::CloudReject;
  std::vector<std::pair<RawCloud, std::optional<CloudReject>>> cases;
  cases.emplace_back(xyzCloud(50), std::nullopt);     // valid, float32
  cases.emplace_back(xyzCloud(50, 8), std::nullopt);  // valid, float64
  {
    RawCloud c = xyzCloud(50);
    c.point_step = 8;  // z ends past the point
    c.row_step = 400;
    cases.emplace_back(c, CloudReject::kFieldPastPoint);
  }
  {
    RawCloud c = xyzCloud(50);
    c.data.resize(c.data.size() - 1);
    cases.emplace_back(c, CloudReject::kDataTooShort);
  }
  {
    RawCloud c = xyzCloud(50);
    c.fields[1].offset = 100;
    cases.emplace_back(c, CloudReject::kFieldPastPoint);
  }
  {
    RawCloud c = xyzCloud(50);
    c.width = 0xFFFFFFFFU;
    c.height = 0xFFFFFFFFU;
    cases.emplace_back(c, CloudReject::kTooManyPoints);
  }
  {
    RawCloud c = xyzCloud(50);
    c.fields.pop_back();
    c.names.pop_back();
    cases.emplace_back(c, CloudReject::kMissingXyz);
  }
  {
    RawCloud c = xyzCloud(50);
    c.fields[0].datatype = 4;  // uint16 x
    cases.emplace_back(c, CloudReject::kUnsupportedXyz);
  }
  {
    RawCloud c = xyzCloud(50);  // big-endian float32: converted
    c.big = true;
    for (std::size_t i = 0; i < c.data.size(); i += 4) std::reverse(&c.data[i], &c.data[i + 4]);
    cases.emplace_back(c, std::nullopt);
  }
  std::array<std::uint64_t, ros2::kCloudRejectCount> expected{};
  std::size_t valid = 0;
  for (auto& [cloud, reason] : cases) {
    // At a sensor's pace: the server's reader keeps the last 5 clouds (ROS sensor QoS); 10 Hz
    // leaves it room when the machine is loaded.
    std::this_thread::sleep_for(100ms);
    publish(*writer, cloud);
    if (reason) {
      ++expected[static_cast<std::size_t>(*reason)];
    } else {
      ++valid;
    }
  }
  RawCloud lost = xyzCloud(10);
  lost.frame = "nowhere";  // no transform ever: dropped after tf_wait
  publish(*writer, lost);
  const std::size_t total = cases.size() + 1;
  const ServerStatus s = waitForStatus(*client, [&](const ServerStatus& st) {
    return st.ros_received == total && st.ros_no_transform == 1 && st.integrated == valid;
  });
  EXPECT_EQ(s.ros_received, total);
  EXPECT_EQ(s.ros_submitted, valid);
  EXPECT_EQ(s.integrated, valid);
  EXPECT_EQ(s.ros_rejected, total - valid - 1);
  EXPECT_EQ(s.ros_no_transform, 1U);
  ASSERT_EQ(s.ros_rejected_by_reason.size(), expected.size());
  for (std::size_t r = 0; r < expected.size(); ++r) {
    EXPECT_EQ(s.ros_rejected_by_reason[r], expected[r])
        << ros2::cloudRejectName(static_cast<CloudReject>(r));
  }
  // Still answering, and the valid clouds are in the map: (2, 0, 0.5) was hit three times.
  auto answer = client->queryPoints({Point3f(2.0F, 0.0F, 0.5F)});
  ASSERT_TRUE(answer);
  EXPECT_EQ(answer->states[0], CellState::kOccupied);
  EXPECT_EQ(server.stop(), 0);
}

TEST(Ros2Wire, TopicAndTypeNamesFollowRmwCycloneddsConventions) {
  EXPECT_EQ(ros2::ddsTopicName("/points"), "rt/points");
  EXPECT_EQ(ros2::ddsTopicName("points"), "rt/points");
  EXPECT_EQ(ros2::ddsTopicName("/robot1/points"), "rt/robot1/points");
  EXPECT_EQ(ros2::ddsTopicName("/tf_static"), "rt/tf_static");
  EXPECT_EQ(ros2::ddsTopicName(""), "");
  EXPECT_EQ(ros2::ddsTopicName("/points/"), "");
  EXPECT_EQ(ros2::ddsTopicName("/bad name"), "");
  // A robot's topics under its namespace.
  EXPECT_EQ(ros2::inNamespace("/robot1", "/points"), "/robot1/points");
  EXPECT_EQ(ros2::inNamespace("robot1", "points"), "/robot1/points");
  EXPECT_EQ(ros2::inNamespace("/fleet/robot1", "tf"), "/fleet/robot1/tf");
  EXPECT_EQ(ros2::inNamespace("", "/points"), "/points");
  EXPECT_EQ(ros2::inNamespace("/", "tf_static"), "/tf_static");
  EXPECT_EQ(ros2::inNamespace("/robot 1", "tf"), "");
  EXPECT_EQ(ros2::inNamespace("/robot1/", "tf"), "");
  EXPECT_EQ(ros2::inNamespace("/robot1", ""), "");
  EXPECT_EQ(ros2::namespaceOfCloud("rt/robot1/points", "/points"), "/robot1");
  EXPECT_EQ(ros2::namespaceOfCloud("rt/fleet/r2/points", "points"), "/fleet/r2");
  EXPECT_EQ(ros2::namespaceOfCloud("rt/points", "/points"), "");
  EXPECT_EQ(ros2::namespaceOfCloud("rt/robot1/points_raw", "/points"), "");
  EXPECT_EQ(ros2::namespaceOfCloud("densemap/scan", "/points"), "");
  EXPECT_TRUE(ros2::matchesGlob("/robot*", "/robot12"));
  EXPECT_TRUE(ros2::matchesGlob("/robot*", "/robot"));
  EXPECT_TRUE(ros2::matchesGlob("/r?bot_*/a*", "/robot_7/arm"));
  EXPECT_TRUE(ros2::matchesGlob("*", "/anything"));
  EXPECT_FALSE(ros2::matchesGlob("/robot*", "/rover1"));
  EXPECT_FALSE(ros2::matchesGlob("/robot?", "/robot12"));
  EXPECT_FALSE(ros2::matchesGlob("/robot", "/robot1"));
  EXPECT_STREQ(sensor_msgs_msg_dds__PointCloud2__desc.m_typename,
               "sensor_msgs::msg::dds_::PointCloud2_");
  EXPECT_STREQ(tf2_msgs_msg_dds__TFMessage__desc.m_typename, "tf2_msgs::msg::dds_::TFMessage_");
  EXPECT_STREQ(octomap_msgs_msg_dds__Octomap__desc.m_typename, "octomap_msgs::msg::dds_::Octomap_");
  EXPECT_STREQ(nav_msgs_msg_dds__OccupancyGrid__desc.m_typename,
               "nav_msgs::msg::dds_::OccupancyGrid_");
}

// As rmw_cyclonedds (humble serdata.cpp), the ROS types carry no type
// information and the rt/ endpoints offer XCDR1 only, so peers stricter than Fast DDS 2.x
// match the server as they match a ROS node.
TEST(Ros2Wire, RosEndpointsOfferXcdr1OnlyAndNoTypeInformation) {
  for (const dds_topic_descriptor_t* d :
       {&sensor_msgs_msg_dds__PointCloud2__desc, &tf2_msgs_msg_dds__TFMessage__desc,
        &octomap_msgs_msg_dds__Octomap__desc, &nav_msgs_msg_dds__OccupancyGrid__desc,
        &rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc,
        &densemap_rmw_gid16_msg_dds__ParticipantEntitiesInfo__desc}) {
    EXPECT_EQ(d->m_flagset & DDS_TOPIC_XTYPES_METADATA, 0U) << d->m_typename;
    EXPECT_EQ(d->type_information.sz, 0U) << d->m_typename;
  }
  auto participant = dds::createParticipant({157, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto topic = dds::createTopic(*participant, sensor_msgs_msg_dds__PointCloud2__desc,
                                ros2::ddsTopicName("/points"));
  ASSERT_TRUE(topic);
  const auto offered = [](const dds::Entity& e) {
    dds_qos_t* qos = dds_create_qos();
    std::vector<dds_data_representation_id_t> out;
    uint32_t n = 0;
    dds_data_representation_id_t* values = nullptr;
    if (dds_get_qos(e.get(), qos) == DDS_RETCODE_OK &&
        dds_qget_data_representation(qos, &n, &values)) {
      out.assign(values, values + n);
      dds_free(values);
    }
    dds_delete_qos(qos);
    return out;
  };
  const std::vector<dds_data_representation_id_t> xcdr1{DDS_DATA_REPRESENTATION_XCDR1};
  for (const dds::QosSpec& q : {dds::rosCloudQos(false), dds::rosCloudQos(true), dds::kTfQos,
                                dds::kTfStaticReaderQos, dds::kLatchedQos}) {
    auto reader = dds::createReader(*participant, *topic, q);
    auto writer = dds::createWriter(*participant, *topic, q);
    ASSERT_TRUE(reader && writer);
    EXPECT_EQ(offered(*reader), xcdr1);
    EXPECT_EQ(offered(*writer), xcdr1);
  }
}

#endif

#ifndef DENSEMAP_ROS2_REALDATA
/// The DDS GUIDs of the endpoints on `topic` that the builtin topic `builtin` (DCPSPublication
/// or DCPSSubscription) reports, with their participants', within 10 s of the first.
std::vector<std::pair<dds_guid_t, dds_guid_t>> endpointsOn(const dds::Entity& participant,
                                                           dds_entity_t builtin,
                                                           const std::string& topic) {
  const dds_entity_t reader = dds_create_reader(participant.get(), builtin, nullptr, nullptr);
  std::vector<std::pair<dds_guid_t, dds_guid_t>> found;
  for (int i = 0; i < 100 && found.empty(); ++i) {
    std::this_thread::sleep_for(100ms);
    void* samples[64] = {};
    dds_sample_info_t infos[64];
    const dds_return_t n = dds_read(reader, samples, infos, 64, 64);
    for (dds_return_t k = 0; k < n; ++k) {
      const auto* e = static_cast<const dds_builtintopic_endpoint_t*>(samples[k]);
      if (infos[k].valid_data && e->topic_name != nullptr && topic == e->topic_name) {
        found.emplace_back(e->key, e->participant_key);
      }
    }
    if (n > 0) dds_return_loan(reader, samples, n);
  }
  dds_delete(reader);
  return found;
}

/// Whether `gid` (a Gid's bytes) is `guid` followed by zeros.
bool gidIs(const unsigned char* gid, std::size_t size, const dds_guid_t& guid) {
  if (std::memcmp(gid, guid.v, sizeof guid.v) != 0) return false;
  return std::all_of(gid + sizeof guid.v, gid + size, [](unsigned char b) { return b == 0; });
}

/// The server's ros_discovery_info in `layout`'s message (Humble's or Iron's), checked against
/// the endpoints discovery reports: the participant, the node's name, its cloud reader and its
/// map writers.
template <class Info>
void checkRosNode(std::uint32_t domain, const std::string& ros2_extra,
                  const dds_topic_descriptor_t& descriptor, const std::string& node_name) {
  test::TempDir dir;
  test::ServerProcess server(dir.path(), domain,
                             "ros2 { enabled: true publish_period_s: 0.2 " + ros2_extra + " }\n");
  auto participant = dds::createParticipant({domain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  dds_topic_descriptor_t named = descriptor;  // the type name ROS nodes use, whatever the layout
  named.m_typename = rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_typename;
  auto topic = dds::createTopic(*participant, named, "ros_discovery_info");
  ASSERT_TRUE(topic);
  auto reader = dds::createReader(*participant, *topic, dds::kLatchedQos);
  ASSERT_TRUE(reader);
  const auto writers = endpointsOn(*participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION,
                                   ros2::ddsTopicName("/octomap_binary"));
  const auto readers =
      endpointsOn(*participant, DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, ros2::ddsTopicName("/points"));
  ASSERT_EQ(writers.size(), 1U);
  ASSERT_EQ(readers.size(), 1U);
  const dds_guid_t server_participant = writers[0].second;
  bool got = false;
  for (int i = 0; i < 100 && !got; ++i) {
    std::this_thread::sleep_for(100ms);
    dds::forEachSample<Info>(*reader, false, [&](const Info& info) {
      got = true;
      EXPECT_TRUE(gidIs(info.gid.data, sizeof info.gid.data, server_participant));
      ASSERT_EQ(info.node_entities_info_seq._length, 1U);
      const auto& node = info.node_entities_info_seq._buffer[0];
      EXPECT_STREQ(node.node_namespace, "/");
      EXPECT_EQ(std::string(node.node_name), node_name);
      const auto contains = [](const auto& seq, const dds_guid_t& guid) {
        for (std::uint32_t k = 0; k < seq._length; ++k) {
          if (gidIs(seq._buffer[k].data, sizeof seq._buffer[k].data, guid)) return true;
        }
        return false;
      };
      EXPECT_TRUE(contains(node.writer_gid_seq, writers[0].first));
      EXPECT_TRUE(contains(node.reader_gid_seq, readers[0].first));
      EXPECT_EQ(node.writer_gid_seq._length, 3U);  // octomap, grid, centres
      EXPECT_EQ(node.reader_gid_seq._length, 3U);  // /points, /tf, /tf_static
    });
  }
  EXPECT_TRUE(got) << "no ros_discovery_info from the server in 10 s";
  EXPECT_EQ(server.stop(), 0);
}

// `ros2 node list` lists what rmw implementations announce on
// ros_discovery_info; the server announces itself there in its robot's layout (Humble's gids
// have 24 bytes, Iron's and later 16).
TEST(Ros2Wire, TheServerIsARosNodeOnRosDiscoveryInfoInItsDistributionsLayout) {
  checkRosNode<rmw_dds_common_msg_dds__ParticipantEntitiesInfo_>(
      174, "distro: \"humble\" node_name: \"mapper_1\"",
      rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc, "mapper_1");
  checkRosNode<densemap_rmw_gid16_msg_dds__ParticipantEntitiesInfo_>(
      175, "", densemap_rmw_gid16_msg_dds__ParticipantEntitiesInfo__desc, "densemap_server");
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
// As octomap_server, an empty map is not published on the map topics (no
// 0-byte Octomap), and a viewer that leaves and returns gets the unchanged map once (from the
// writer's transient-local history), not a second copy.
TEST(Ros2Wire, AnEmptyMapIsNotPublishedAndAReturningViewerGetsTheMapOnce) {
  constexpr std::uint32_t kDomain = 154;
  test::TempDir dir;
  ASSERT_TRUE(writeSmallIndoorScans(dir.path() / "data", 2));
  test::ServerProcess server(dir.path(), kDomain, kRosConfig);
  auto client = connect(kDomain);
  ASSERT_TRUE(client);
  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto topic = dds::createTopic(*participant, octomap_msgs_msg_dds__Octomap__desc,
                                ros2::ddsTopicName("/octomap_binary"));
  ASSERT_TRUE(topic);
  const dds::QosSpec latched{.depth = 1, .transient_local = true};
  const auto samplesWithin = [&](const dds::Entity& reader, std::chrono::milliseconds wait) {
    std::size_t n = 0;
    for (const auto end = std::chrono::steady_clock::now() + wait;
         std::chrono::steady_clock::now() < end;) {
      n += dds::takeAll<octomap_msgs_msg_dds__Octomap_>(
          reader, [](const octomap_msgs_msg_dds__Octomap_& m) { EXPECT_GT(m.data._length, 0U); });
      std::this_thread::sleep_for(20ms);
    }
    return n;
  };
  {
    auto viewer = dds::createReader(*participant, *topic, latched);
    ASSERT_TRUE(viewer);
    // The empty map: nothing in 1.5 s (7 publish periods).
    EXPECT_EQ(samplesWithin(*viewer, 1500ms), 0U);
    ASSERT_EQ(runCli("--domain-id " + std::to_string(kDomain) + " replay --data " +
                     (dir.path() / "data").string() + " --rate 10"),
              0);
    const ServerStatus s =
        waitForStatus(*client, [](const ServerStatus& st) { return st.integrated >= 2; });
    ASSERT_EQ(s.integrated, 2U);
    EXPECT_GE(samplesWithin(*viewer, 1500ms), 1U);
  }
  // The viewer left; the map is unchanged. A returning viewer gets it exactly once.
  std::this_thread::sleep_for(1s);
  // Depth 2: a second copy written right after the history's would be kept, not replace it.
  auto returning = dds::createReader(*participant, *topic, {.depth = 2, .transient_local = true});
  ASSERT_TRUE(returning);
  EXPECT_EQ(samplesWithin(*returning, 2000ms), 1U);
  EXPECT_EQ(server.stop(), 0);
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
// A robot whose clouds never arrive is explained in the status: a best-effort
// publisher against reliable_clouds: true is refused for its reliability (DDS's incompatible
// QoS status), a matching one is counted as a matched writer.
TEST(Ros2Wire, StatusSaysWhichCloudWritersMatchAndWhichWereRefusedForTheirQos) {
  constexpr std::uint32_t kDomain = 155;
  test::TempDir dir;
  test::ServerProcess server(dir.path(), kDomain, kRosConfig);  // reliable_clouds: true
  auto client = connect(kDomain);
  ASSERT_TRUE(client);
  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto topic = dds::createTopic(*participant, sensor_msgs_msg_dds__PointCloud2__desc,
                                ros2::ddsTopicName("/points"));
  ASSERT_TRUE(topic);
  auto best_effort = dds::createWriter(*participant, *topic, {.reliable = false, .depth = 5});
  ASSERT_TRUE(best_effort);
  const auto cloudTopic = [](const ServerStatus& s) -> const RosCloudTopicStatus* {
    for (const auto& c : s.ros_clouds) {
      if (c.topic == "/points") return &c;
    }
    return nullptr;
  };
  ServerStatus s = waitForStatus(*client, [&](const ServerStatus& st) {
    const auto* c = cloudTopic(st);
    return c != nullptr && c->incompatible_qos > 0;
  });
  const RosCloudTopicStatus* refused = cloudTopic(s);
  ASSERT_NE(refused, nullptr);
  EXPECT_GE(refused->incompatible_qos, 1U);
  EXPECT_EQ(refused->last_incompatible_policy, "reliability");
  EXPECT_EQ(refused->matched_writers, 0U);
  auto reliable = dds::createWriter(*participant, *topic, {.depth = 5});
  ASSERT_TRUE(reliable);
  s = waitForStatus(*client, [&](const ServerStatus& st) {
    const auto* c = cloudTopic(st);
    return c != nullptr && c->matched_writers == 1;
  });
  ASSERT_NE(cloudTopic(s), nullptr);
  EXPECT_EQ(cloudTopic(s)->matched_writers, 1U);
  // The CLI says it in words.
  std::string printed;
  {
    FILE* pipe = popen(
        (std::string(DENSEMAP_CLI_BIN) + " --domain-id " + std::to_string(kDomain) + " status 2>&1")
            .c_str(),
        "r");
    ASSERT_NE(pipe, nullptr);
    char buf[512];
    while (std::fgets(buf, sizeof buf, pipe) != nullptr) printed += buf;
    pclose(pipe);
  }
  EXPECT_NE(printed.find("ros2 cloud topic /points: 1 writer matched"), std::string::npos)
      << printed;
  EXPECT_NE(printed.find("refused for incompatible QoS (last: reliability"), std::string::npos)
      << printed;
  EXPECT_EQ(server.stop(), 0);
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
// With the default config, clouds that arrive before a late /tf_static (a
// Fast DDS broadcaster's sample reaches Cyclone at its next heartbeat, ~3 s) wait for it and
// are all integrated, as octomap_server's TF filter keeps them (5 clouds, 5 s).
TEST(Ros2Wire, CloudsBeforeALateTfStaticWaitForItWithTheDefaultConfig) {
  constexpr std::uint32_t kDomain = 156;
  test::TempDir dir;
  ASSERT_TRUE(writeSmallIndoorScans(dir.path() / "data", 10));
  test::ServerProcess server(dir.path(), kDomain,
                             "ros2 { enabled: true reliable_clouds: true publish_period_s: 0 }\n");
  auto client = connect(kDomain);
  ASSERT_TRUE(client);
  // 10 scans at 10 Hz: /tf_static goes out 2 s after the first, after the last cloud.
  ASSERT_EQ(runCli("--domain-id " + std::to_string(kDomain) + " replay --ros --data " +
                   (dir.path() / "data").string() + " --rate 10 --ros-static-delay 2"),
            0);
  const ServerStatus s =
      waitForStatus(*client, [](const ServerStatus& st) { return st.integrated >= 10; });
  EXPECT_EQ(s.ros_received, 10U);
  EXPECT_EQ(s.ros_no_transform, 0U);
  EXPECT_EQ(s.integrated, 10U);
  EXPECT_EQ(server.stop(), 0);
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
// A node that announces itself only by multicast (Humble with
// ROS_LOCALHOST_ONLY=1) never reaches the server, which has multicast off on loopback: it is
// found when the server's own unicast announcement reaches its discovery port. Such a node is
// played by a Cyclone participant with no multicast whose one peer is a port nobody listens on
// (it announces itself to no one, and listens on 7410 + 250 d + 2 i as every participant
// does; with no peer at all Cyclone 0.10 announces to localhost); its cloud writer must match
// the server's reader within about a second of being created. Before the server announced
// every second it took 7.06 s (twice; Cyclone's default period).
TEST(Ros2Wire, ANodeThatOnlyListensForUnicastDiscoveryFindsTheServerWithinASecond) {
  constexpr std::uint32_t kDomain = 158;
  test::TempDir dir;
  test::ServerProcess server(dir.path(), kDomain,
                             "ros2 { enabled: true reliable_clouds: false publish_period_s: 0 }\n");
  // The server is up (a separate process asks: this process's domain must keep the silent
  // configuration below, which its first participant fixes).
  ASSERT_EQ(runCli("--domain-id " + std::to_string(kDomain) + " status"), 0);
  const std::string silent =
      "<CycloneDDS><Domain Id=\"any\"><General><Interfaces><NetworkInterface name=\"lo\"/>"
      "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
      "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>119"
      "</MaxAutoParticipantIndex><Peers><Peer Address=\"127.0.0.1:9\"/></Peers></Discovery>"
      "</Domain></CycloneDDS>";
  const dds_entity_t domain = dds_create_domain(kDomain, silent.c_str());
  ASSERT_GT(domain, 0) << dds_strretcode(domain);
  const dds_entity_t participant = dds_create_participant(kDomain, nullptr, nullptr);
  ASSERT_GT(participant, 0) << dds_strretcode(participant);
  const dds_entity_t topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__PointCloud2__desc,
                       ros2::ddsTopicName("/points").c_str(), nullptr, nullptr);
  ASSERT_GT(topic, 0) << dds_strretcode(topic);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 5);
  const dds_entity_t writer = dds_create_writer(participant, topic, qos, nullptr);
  dds_delete_qos(qos);
  ASSERT_GT(writer, 0) << dds_strretcode(writer);
  const auto start = std::chrono::steady_clock::now();
  double matched_after_s = -1;
  while (std::chrono::steady_clock::now() - start < std::chrono::seconds(15)) {
    dds_publication_matched_status_t m{};
    if (dds_get_publication_matched_status(writer, &m) >= 0 && m.current_count > 0) {
      matched_after_s =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  dds_delete(domain);
  ASSERT_GE(matched_after_s, 0.0) << "the server's cloud reader never matched in 15 s";
  EXPECT_LT(matched_after_s, 2.0) << "matched after " << matched_after_s << " s";
  EXPECT_EQ(server.stop(), 0);
}
#endif

#ifndef DENSEMAP_ROS2_REALDATA
// A SLAM system's corrected trajectory as nav_msgs/Path: the server turns each base pose into
// the pose of the robot's cloud topic (times the base -> sensor transform of its TF tree) and
// re-integrates; the map it then serves equals the offline map of the clouds with those poses.
TEST(Ros2Wire, ACorrectedPathReplacesTheCloudsPosesAndTheMapFollows) {
  constexpr std::uint32_t kDomain = 210;
  constexpr std::size_t kScans = 12, kCorrected = 6;
  test::TempDir dir;
  ASSERT_TRUE(writeSmallIndoorScans(dir.path() / "data", kScans));
  test::ServerProcess server(
      dir.path(), kDomain,
      "ros2 { enabled: true reliable_clouds: true world_frame: \"map\" tf_wait_s: 3\n"
      "       corrected_path_topic: \"/corrected_path\" base_frame: \"base_link\" }\n"
      "history { enabled: true directory: \"" +
          (dir.path() / "history").string() + "\" checkpoint_every: 4 }\n");
  auto client = connect(kDomain);
  ASSERT_TRUE(client);
  ros2::ReplayFrames frames;
  frames.stamp_base_ns = kStampBase;
  frames.period_ns = static_cast<std::int64_t>(1e9 / kRate);
  frames.stamp_offset = 0.5;
  ASSERT_EQ(
      runCli("--domain-id " + std::to_string(kDomain) + " replay --ros --data " +
             (dir.path() / "data").string() + " --limit " + std::to_string(kScans) +
             " --rate 10 --ros-stamp-offset 0.5 --ros-stamp-base-ns " + std::to_string(kStampBase)),
      0);
  waitForStatus(*client, [&](const ServerStatus& s) { return s.integrated == kScans; });
  std::vector<RawScan> raws = rosScans(dir.path() / "data", 0, kScans, frames, "/points");
  const auto config = dir.path() / "server.textproto";
  const auto before = offlineMap(raws, config);

  // The corrected base poses: the last six moved 0.3 m and turned 0.05 rad, as a loop closure
  // moves them. Their sensor poses are what the server computes: path pose times the mount.
  ros2::TfBuffer tf;
  ASSERT_TRUE(tf.set(frames.base, frames.sensor, ros2::sensorMount(), true));
  const Eigen::Isometry3d fix =
      Eigen::Translation3d(0.3, -0.2, 0.0) * Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitZ());
  std::vector<geometry_msgs_msg_dds__PoseStamped_> poses;
  for (std::size_t k = kScans - kCorrected; k < kScans; ++k) {
    const std::int64_t stamp = frames.cloudStamp(k);
    auto mount = tf.lookup(frames.base, frames.sensor, stamp);
    ASSERT_TRUE(mount);
    const Eigen::Isometry3d base =
        fix * ros2::fromScanPose(raws[k].t_world_sensor, raws[k].q_world_sensor) * mount->inverse();
    const ScanPose p = toScanPose(base);
    geometry_msgs_msg_dds__PoseStamped_ ps{};
    ps.header.stamp.sec = static_cast<std::int32_t>(stamp / 1'000'000'000);
    ps.header.stamp.nanosec = static_cast<std::uint32_t>(stamp % 1'000'000'000);
    ps.header.frame_id = const_cast<char*>("map");
    ps.pose.position = {p.t[0], p.t[1], p.t[2]};
    ps.pose.orientation = {p.q[1], p.q[2], p.q[3], p.q[0]};
    poses.push_back(ps);
    const ScanPose sensor = toScanPose(ros2::fromScanPose(p.t, p.q) * *mount);
    raws[k].t_world_sensor = sensor.t;
    raws[k].q_world_sensor = sensor.q;
  }
  const auto corrected = offlineMap(raws, config);

  auto participant = dds::createParticipant({kDomain, "lo", std::nullopt});
  ASSERT_TRUE(participant);
  auto topic = dds::createTopic(*participant, nav_msgs_msg_dds__Path__desc,
                                ros2::ddsTopicName("/corrected_path"));
  ASSERT_TRUE(topic);
  auto writer = dds::createWriter(*participant, *topic, dds::kRosPathQos);
  ASSERT_TRUE(writer);
  dds_publication_matched_status_t matched{};
  for (int i = 0; i < 500 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(writer->get(), &matched);
    std::this_thread::sleep_for(10ms);
  }
  ASSERT_EQ(matched.current_count, 1U) << "the server's path reader";
  nav_msgs_msg_dds__Path_ path{};
  path.header.frame_id = const_cast<char*>("map");
  path.poses._buffer = poses.data();
  path.poses._length = path.poses._maximum = static_cast<std::uint32_t>(poses.size());
  ASSERT_TRUE(dds::write(*writer, &path));

  const ServerStatus status =
      waitForStatus(*client, [](const ServerStatus& s) { return s.history.reintegrations == 1; });
  EXPECT_EQ(status.history.corrected_scans, kCorrected);
  EXPECT_EQ(status.history.unmatched_poses, 0U);
  auto fetched = client->fetchMap(status.history.last_version);
  ASSERT_TRUE(fetched) << fetched.error().message;
  expectSameMap(testing::gridOf(*fetched), *corrected);
  // The correction moved the map: the check above would catch a path that was not applied.
  GridMap before_map(0.2, SensorModel{}), after_map(0.2, SensorModel{});
  before->forEachKnown([&](const VoxelKey& k, float v) { before_map.setLogOdds(k, v); });
  corrected->forEachKnown([&](const VoxelKey& k, float v) { after_map.setLogOdds(k, v); });
  EXPECT_GT(diffMaps(before_map, after_map).differing(), 1000U);
  EXPECT_EQ(server.stop(), 0);
}
#endif

}  // namespace
}  // namespace densemap
