// A ROS 2 robot and viewer on eProsima Fast DDS (ROS 2's default middleware), against
// densemap-server (a foreign vendor, not our own Cyclone participants agreeing with
// themselves). Types from idl/ros2 by fastddsgen; loopback only (UDPv4 to 127.0.0.1, optionally
// Fast DDS's shared memory beside it), initial peers 127.0.0.1, no multicast sent.
//   robot:  /tf_static (map -> odom, base_link -> lidar), then per scan /tf (odom -> base_link)
//           and a PointCloud2 in lidar on /points at 10 Hz, as densemap replay --ros does;
//   viewer: a late joiner (a new participant after the robot is done) that takes
//           /octomap_binary and /projected_map from the transient-local history and writes
//           the octomap as OctoMap's .bt (OUT/viewer.bt) and the grid's size and cells
//           (OUT/grid.txt).
// Usage: fastdds_ros_peer DOMAIN DATASET SCANS udp|udp+shm reliable|best_effort OUT_DIR [early]
//        early: /tf_static is written before the server is there (a robot started first; the
//        server must get it from the transient-local history when it joins)
//        fastdds_ros_peer --compare A.bt B.bt GRID_TXT   (exit 0: the same known cells with the
//        same occupancy, and the grid's occupied and free columns those of A's cells)
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>
#include <octomap/OcTree.h>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>

#include "densemap/io/scan_source.hpp"
#include "densemap/ros2/replay_frames.hpp"
#include "nav_msgsPubSubTypes.h"
#include "octomap_msgsPubSubTypes.h"
#include "sensor_msgsPubSubTypes.h"
#include "tf2_msgsPubSubTypes.h"

using namespace eprosima::fastdds::dds;
using namespace std::chrono_literals;
namespace rtps = eprosima::fastdds::rtps;

namespace {

DomainParticipant* makeParticipant(int domain, bool shm, const char* name) {
  DomainParticipantQos qos;
  qos.name(name);
  qos.transport().use_builtin_transports = false;
  auto udp = std::make_shared<rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList.emplace_back("127.0.0.1");
  qos.transport().user_transports.push_back(udp);
  if (shm)
    qos.transport().user_transports.push_back(
        std::make_shared<rtps::SharedMemTransportDescriptor>());
  // Discovery by unicast on loopback only: announce to 127.0.0.1 (participant indices 0..).
  eprosima::fastrtps::rtps::Locator_t peer;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  qos.wire_protocol().builtin.initialPeersList.push_back(peer);
  eprosima::fastrtps::rtps::Locator_t own;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(own, 127, 0, 0, 1);
  qos.wire_protocol().builtin.metatrafficUnicastLocatorList.push_back(own);
  qos.wire_protocol().default_unicast_locator_list.push_back(own);
  return DomainParticipantFactory::get_instance()->create_participant(domain, qos);
}

DataWriterQos writerQos(bool reliable, bool transient_local, int depth) {
  DataWriterQos q = DATAWRITER_QOS_DEFAULT;
  q.reliability().kind = reliable ? RELIABLE_RELIABILITY_QOS : BEST_EFFORT_RELIABILITY_QOS;
  q.durability().kind = transient_local ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
  q.history().kind = KEEP_LAST_HISTORY_QOS;
  q.history().depth = depth;
  return q;
}

bool waitForMatch(DataWriter* w, std::chrono::seconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  PublicationMatchedStatus s;
  while (std::chrono::steady_clock::now() < end) {
    if (w->get_publication_matched_status(s) == ReturnCode_t::RETCODE_OK && s.current_count > 0) {
      return true;
    }
    std::this_thread::sleep_for(20ms);
  }
  return false;
}

geometry_msgs::msg::dds_::TransformStamped_ transform(const std::string& parent,
                                                      const std::string& child,
                                                      const densemap::ros2::TfSample& s,
                                                      std::int64_t stamp) {
  geometry_msgs::msg::dds_::TransformStamped_ t;
  t.header().stamp().sec(static_cast<int32_t>(stamp / 1'000'000'000));
  t.header().stamp().nanosec(static_cast<uint32_t>(stamp % 1'000'000'000));
  t.header().frame_id(parent);
  t.child_frame_id(child);
  t.transform().translation().x(s.t.x());
  t.transform().translation().y(s.t.y());
  t.transform().translation().z(s.t.z());
  t.transform().rotation().x(s.q.x());
  t.transform().rotation().y(s.q.y());
  t.transform().rotation().z(s.q.z());
  t.transform().rotation().w(s.q.w());
  return t;
}

int robot(int domain, const std::string& data, std::size_t scans, bool shm, bool reliable,
          bool early) {
  auto source = densemap::openScanSource(data);
  if (!source) {
    std::fprintf(stderr, "robot: %s\n", source.error().message.c_str());
    return 1;
  }
  DomainParticipant* p = makeParticipant(domain, shm, "fastdds_robot");
  if (p == nullptr) return 1;
  TypeSupport cloud_type(new sensor_msgs::msg::dds_::PointCloud2_PubSubType());
  TypeSupport tf_type(new tf2_msgs::msg::dds_::TFMessage_PubSubType());
  cloud_type.register_type(p);
  tf_type.register_type(p);
  Topic* points = p->create_topic("rt/points", cloud_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Topic* tf = p->create_topic("rt/tf", tf_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Topic* tf_static = p->create_topic("rt/tf_static", tf_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Publisher* pub = p->create_publisher(PUBLISHER_QOS_DEFAULT);
  DataWriter* cloud_w = pub->create_datawriter(points, writerQos(reliable, false, 5));
  DataWriter* tf_w = pub->create_datawriter(tf, writerQos(true, false, 100));
  DataWriter* static_w = pub->create_datawriter(tf_static, writerQos(true, true, 1));
  if (cloud_w == nullptr || tf_w == nullptr || static_w == nullptr) return 1;
  densemap::ros2::ReplayFrames frames;
  frames.stamp_base_ns = 1'700'000'000'000'000'000;
  tf2_msgs::msg::dds_::TFMessage_ statics;
  statics.transforms().push_back(
      transform(frames.map, frames.odom, densemap::ros2::TfSample{}, frames.stampOf(0)));
  statics.transforms().push_back(
      transform(frames.base, frames.sensor, densemap::ros2::sensorMount(), frames.stampOf(0)));
  if (early) static_w->write(&statics);
  if (!waitForMatch(cloud_w, 20s) || !waitForMatch(tf_w, 20s)) {
    std::fprintf(stderr, "robot: the server's readers were not matched in 20 s\n");
    return 1;
  }
  if (!early) static_w->write(&statics);
  const std::size_t n = std::min(scans, (*source)->size());
  for (std::size_t k = 0; k < n; ++k) {
    auto scan = (*source)->load(k);
    if (!scan) return 1;
    const std::int64_t stamp = frames.stampOf(k);
    tf2_msgs::msg::dds_::TFMessage_ moving;
    moving.transforms().push_back(transform(
        frames.odom, frames.base, densemap::ros2::odomToBase(scan->T_world_sensor, stamp), stamp));
    tf_w->write(&moving);
    sensor_msgs::msg::dds_::PointCloud2_ c;
    c.header().stamp().sec(static_cast<int32_t>(stamp / 1'000'000'000));
    c.header().stamp().nanosec(static_cast<uint32_t>(stamp % 1'000'000'000));
    c.header().frame_id(frames.sensor);
    c.height(1);
    c.width(static_cast<uint32_t>(scan->points.size()));
    const char* names[] = {"x", "y", "z"};
    for (uint32_t i = 0; i < 3; ++i) {
      sensor_msgs::msg::dds_::PointField_ f;
      f.name(names[i]);
      f.offset(4 * i);
      f.datatype(7);  // FLOAT32
      f.count(1);
      c.fields().push_back(f);
    }
    c.point_step(12);
    c.row_step(12 * c.width());
    c.data().resize(12 * scan->points.size());
    for (std::size_t i = 0; i < scan->points.size(); ++i) {
      const float xyz[3] = {scan->points[i].x(), scan->points[i].y(), scan->points[i].z()};
      std::memcpy(c.data().data() + 12 * i, xyz, 12);
    }
    c.is_dense(true);
    cloud_w->write(&c);
    std::this_thread::sleep_for(100ms);
  }
  // Let reliable samples go out before the participant leaves.
  cloud_w->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(5, 0));
  tf_w->wait_for_acknowledgments(eprosima::fastrtps::Duration_t(5, 0));
  std::this_thread::sleep_for(500ms);
  p->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(p);
  std::printf("robot: sent %zu clouds\n", n);
  return 0;
}

int viewer(int domain, bool shm, const std::string& out) {
  DomainParticipant* p = makeParticipant(domain, shm, "fastdds_viewer");
  if (p == nullptr) return 1;
  TypeSupport octomap_type(new octomap_msgs::msg::dds_::Octomap_PubSubType());
  TypeSupport grid_type(new nav_msgs::msg::dds_::OccupancyGrid_PubSubType());
  octomap_type.register_type(p);
  grid_type.register_type(p);
  Topic* octomap_t =
      p->create_topic("rt/octomap_binary", octomap_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Topic* grid_t = p->create_topic("rt/projected_map", grid_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Subscriber* sub = p->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  DataReaderQos q = DATAREADER_QOS_DEFAULT;
  q.reliability().kind = RELIABLE_RELIABILITY_QOS;
  q.durability().kind = TRANSIENT_LOCAL_DURABILITY_QOS;
  q.history().kind = KEEP_LAST_HISTORY_QOS;
  q.history().depth = 1;
  DataReader* octomap_r = sub->create_datareader(octomap_t, q);
  DataReader* grid_r = sub->create_datareader(grid_t, q);
  octomap_msgs::msg::dds_::Octomap_ map;
  nav_msgs::msg::dds_::OccupancyGrid_ grid;
  bool got_map = false, got_grid = false;
  const auto end = std::chrono::steady_clock::now() + 20s;
  while (std::chrono::steady_clock::now() < end && !(got_map && got_grid)) {
    SampleInfo info;
    if (octomap_r->take_next_sample(&map, &info) == ReturnCode_t::RETCODE_OK && info.valid_data) {
      got_map = true;
    }
    if (grid_r->take_next_sample(&grid, &info) == ReturnCode_t::RETCODE_OK && info.valid_data) {
      got_grid = true;
    }
    std::this_thread::sleep_for(20ms);
  }
  p->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(p);
  if (!got_map || !got_grid) {
    std::fprintf(stderr, "viewer: no %s in 20 s\n", got_map ? "/projected_map" : "/octomap_binary");
    return 1;
  }
  // The message's data is OcTree::writeBinaryData of the server's tree (octomap_msgs'
  // binaryMapToMsg): read it back with OctoMap and write it as a .bt.
  octomap::OcTree tree(map.resolution());
  std::stringstream bytes(std::string(map.data().begin(), map.data().end()));
  tree.readBinaryData(bytes);
  if (map.id() != "OcTree" || !map.binary() || !tree.writeBinary(out + "/viewer.bt")) return 1;
  std::size_t occupied = 0, free = 0;
  for (int8_t v : grid.data()) {
    occupied += v == 100 ? 1 : 0;
    free += v == 0 ? 1 : 0;
  }
  std::ofstream(out + "/grid.txt") << grid.info().width() << " " << grid.info().height() << " "
                                   << occupied << " " << free << "\n";
  std::printf("viewer: octomap %zu bytes, %zu leaves; grid %u x %u, %zu occupied, %zu free\n",
              map.data().size(), tree.getNumLeafNodes(), grid.info().width(), grid.info().height(),
              occupied, free);
  return 0;
}

/// Every known cell at full depth of a .bt (pruned or not), with its occupancy.
std::map<std::tuple<int, int, int>, bool> cellsOf(const std::string& file) {
  std::map<std::tuple<int, int, int>, bool> cells;
  octomap::OcTree tree(0.1);
  if (!tree.readBinary(file)) return cells;
  tree.expand();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const octomap::OcTreeKey k = it.getKey();
    cells[{k[0], k[1], k[2]}] = tree.isNodeOccupied(*it);
  }
  return cells;
}

int compare(const std::string& a, const std::string& b, const std::string& grid_txt) {
  const auto x = cellsOf(a), y = cellsOf(b);
  // /projected_map (no z band): a column is occupied if a cell of it is, free if all are free.
  std::map<std::pair<int, int>, bool> columns;
  for (const auto& [key, occupied] : x) {
    bool& c = columns[{std::get<0>(key), std::get<1>(key)}];
    c = c || occupied;
  }
  std::size_t occupied_columns = 0;
  for (const auto& [column, occupied] : columns) occupied_columns += occupied ? 1 : 0;
  std::size_t width = 0, height = 0, grid_occupied = 0, grid_free = 0;
  std::ifstream(grid_txt) >> width >> height >> grid_occupied >> grid_free;
  std::printf("compare: grid %zu occupied, %zu free columns; the map's %zu and %zu\n",
              grid_occupied, grid_free, occupied_columns, columns.size() - occupied_columns);
  if (grid_occupied != occupied_columns || grid_free != columns.size() - occupied_columns) return 1;
  std::size_t differing = 0;
  for (const auto& [key, occupied] : x) {
    const auto it = y.find(key);
    differing += it == y.end() || it->second != occupied ? 1 : 0;
  }
  for (const auto& [key, occupied] : y) differing += x.contains(key) ? 0 : 1;
  std::printf("compare: %zu and %zu known cells, %zu differing\n", x.size(), y.size(), differing);
  return x.empty() || differing != 0 ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 5 && std::string(argv[1]) == "--compare") return compare(argv[2], argv[3], argv[4]);
  if (argc != 7 && argc != 8) {
    std::fprintf(stderr,
                 "usage: fastdds_ros_peer DOMAIN DATASET SCANS udp|udp+shm "
                 "reliable|best_effort OUT_DIR [early]\n");
    return 2;
  }
  const int domain = std::atoi(argv[1]);
  const bool shm = std::string(argv[4]) == "udp+shm";
  const bool reliable = std::string(argv[5]) == "reliable";
  const bool early = argc == 8 && std::string(argv[7]) == "early";
  if (int rc = robot(domain, argv[2], std::strtoul(argv[3], nullptr, 10), shm, reliable, early);
      rc != 0) {
    return rc;
  }
  std::this_thread::sleep_for(1s);  // the server's next map-topic round
  return viewer(domain, shm, argv[6]);
}
