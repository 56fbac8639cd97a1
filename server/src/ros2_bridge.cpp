#include "densemap/server/ros2_bridge.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>

#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/names.hpp"
#include "densemap/ros2/tf_buffer.hpp"
#include "densemap/wire/topics.hpp"
#include "guarded.hpp"
#include "nav_msgs.h"
#include "octomap_msgs.h"
#include "ros2_bridge_state.hpp"
#include "sensor_msgs.h"
#include "tf2_msgs.h"

namespace densemap::server {
namespace {

using Clock = std::chrono::steady_clock;

std::int64_t stampNs(const builtin_interfaces_msg_dds__Time_& t) {
  return std::int64_t{t.sec} * 1'000'000'000 + t.nanosec;
}

constexpr dds_attach_t kTfTag = 1, kTfStaticTag = 2, kPathTag = 3, kCloudTag0 = 16;

/// A QoS policy's name as DDS specifications spell it (status: why a writer was refused).
std::string policyName(dds_qos_policy_id_t id) {
  switch (id) {
    case DDS_RELIABILITY_QOS_POLICY_ID:
      return "reliability";
    case DDS_DURABILITY_QOS_POLICY_ID:
      return "durability";
    case DDS_DEADLINE_QOS_POLICY_ID:
      return "deadline";
    case DDS_LIVELINESS_QOS_POLICY_ID:
      return "liveliness";
    case DDS_OWNERSHIP_QOS_POLICY_ID:
      return "ownership";
    case DDS_PRESENTATION_QOS_POLICY_ID:
      return "presentation";
    case DDS_DESTINATIONORDER_QOS_POLICY_ID:
      return "destination order";
    case DDS_LATENCYBUDGET_QOS_POLICY_ID:
      return "latency budget";
    case DDS_DATA_REPRESENTATION_QOS_POLICY_ID:
      return "data representation";
    case DDS_TYPE_CONSISTENCY_ENFORCEMENT_QOS_POLICY_ID:
      return "type consistency";
    default:
      return "policy " + std::to_string(static_cast<int>(id));
  }
}

}  // namespace

Ros2Bridge::Ros2Bridge(Ingest& ingest, const Ros2Options& options)
    : ingest_(ingest),
      options_(options),
      dds_(std::make_unique<Dds>()),
      state_(std::make_unique<Topics>()) {}

Ros2Bridge::~Ros2Bridge() { stop(); }

namespace {

Expected<dds::Entity> rosTopic(const dds::Entity& participant, const dds_topic_descriptor_t& desc,
                               const std::string& ros_name) {
  const std::string name = ros2::ddsTopicName(ros_name);
  if (name.empty()) return makeError("ros2: '" + ros_name + "' is not a valid ROS topic name");
  return dds::createTopic(participant, desc, name);
}

}  // namespace

Expected<std::unique_ptr<Ros2Bridge>> Ros2Bridge::create(Ingest& ingest,
                                                         const dds::Entity& participant,
                                                         const Ros2Options& options) {
  std::unique_ptr<Ros2Bridge> bridge(new Ros2Bridge(ingest, options));
  Dds& d = *bridge->dds_;
  d.participant = &participant;
  auto ws = dds::WaitSet::create(participant);
  if (!ws) return std::unexpected(ws.error());
  d.waitset.emplace(std::move(*ws));
  // One robot at the root, or one a namespace: its clouds and its TF tree under it.
  const std::vector<std::string> namespaces =
      options.robots.empty() && options.robot_pattern.empty() ? std::vector<std::string>{""}
                                                              : options.robots;
  for (const std::string& ns : namespaces) {
    if (auto ok = bridge->addRobot(ns); !ok) return std::unexpected(ok.error());
  }
  if (!options.robot_pattern.empty()) {
    const dds_entity_t found =
        dds_create_reader(participant.get(), DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr);
    if (auto ok = dds::check(found, "dds_create_reader(DCPSPublication)"); !ok) {
      return std::unexpected(ok.error());
    }
    d.publications = dds::Entity(found);
  }
  // Maps for late joiners (RViz, Nav2): reliable, transient-local, keep-last 1.
  const dds::QosSpec latched = dds::kLatchedQos;
  auto map_writer = [&](const dds_topic_descriptor_t& desc, const std::string& ros_name,
                        dds::Entity& t_out, dds::Entity& w_out) -> Expected<void> {
    if (ros_name.empty() || options.publish_period_s <= 0) return {};
    auto t = rosTopic(participant, desc, ros_name);
    if (!t) return std::unexpected(t.error());
    auto w = dds::createWriter(participant, *t, latched);
    if (!w) return std::unexpected(w.error());
    t_out = std::move(*t);
    w_out = std::move(*w);
    return {};
  };
  for (auto ok : {map_writer(octomap_msgs_msg_dds__Octomap__desc, options.octomap_topic,
                             d.octomap_topic, d.octomap_writer),
                  map_writer(nav_msgs_msg_dds__OccupancyGrid__desc, options.grid_topic,
                             d.grid_topic, d.grid_writer),
                  map_writer(sensor_msgs_msg_dds__PointCloud2__desc, options.centers_topic,
                             d.centers_topic, d.centers_writer),
                  map_writer(sensor_msgs_msg_dds__PointCloud2__desc,
                             ingest.hasDistanceField() ? options.esdf_slice_topic : "",
                             d.slice_topic, d.slice_writer),
                  map_writer(nav_msgs_msg_dds__OccupancyGrid__desc,
                             ingest.hasDistanceField() ? options.costmap_topic : "",
                             d.costmap_topic, d.costmap_writer)}) {
    if (!ok) return std::unexpected(ok.error());
  }
  if (auto ok = bridge->announce(); !ok) return std::unexpected(ok.error());
  const PipelineOptions& p = ingest.options();
  bridge->state_->map = std::make_unique<ros2::MapTopicsState>(p.resolution_m, options.grid_min_z_m,
                                                               options.grid_max_z_m);
  bridge->latest_ = ingest.view();
  return bridge;
}

Expected<void> Ros2Bridge::addRobot(const std::string& ns) {
  Dds& d = *dds_;
  const dds::Entity& participant = *d.participant;
  // ROS sensor data QoS (best effort, keep last 5) unless told otherwise; a best-effort reader
  // also matches reliable writers.
  const dds::QosSpec cloud_qos = dds::rosCloudQos(options_.reliable_clouds);
  RobotTfReaders tfr;
  auto tf = rosTopic(participant, tf2_msgs_msg_dds__TFMessage__desc, ros2::inNamespace(ns, "tf"));
  auto tf_static =
      rosTopic(participant, tf2_msgs_msg_dds__TFMessage__desc, ros2::inNamespace(ns, "tf_static"));
  if (!tf || !tf_static) return makeError("ros2: cannot create the TF topics of '" + ns + "'");
  tfr.tf_topic = std::move(*tf);
  tfr.tf_static_topic = std::move(*tf_static);
  auto tf_reader = dds::createReader(participant, tfr.tf_topic, dds::kTfQos);
  auto tf_static_reader =
      dds::createReader(participant, tfr.tf_static_topic, dds::kTfStaticReaderQos);
  if (!tf_reader || !tf_static_reader) return makeError("ros2: cannot create the TF readers");
  tfr.tf_reader = std::move(*tf_reader);
  tfr.tf_static_reader = std::move(*tf_static_reader);
  if (const std::string& path = options_.corrected_path_topic; !path.empty()) {
    auto topic = rosTopic(participant, nav_msgs_msg_dds__Path__desc,
                          ns.empty() ? path : ros2::inNamespace(ns, path));
    if (!topic) return std::unexpected(topic.error());
    auto reader = dds::createReader(participant, *topic, dds::kRosPathQos);
    if (!reader) return std::unexpected(reader.error());
    tfr.path_topic = std::move(*topic);
    tfr.path_reader = std::move(*reader);
  }
  std::vector<dds::Entity> topics, readers;
  std::vector<std::string> names;
  for (const std::string& cloud : options_.clouds) {
    const std::string name = ns.empty() ? cloud : ros2::inNamespace(ns, cloud);
    auto t = rosTopic(participant, sensor_msgs_msg_dds__PointCloud2__desc, name);
    if (!t) return std::unexpected(t.error());
    auto r = dds::createReader(participant, *t, cloud_qos);
    if (!r) return std::unexpected(r.error());
    topics.push_back(std::move(*t));
    readers.push_back(std::move(*r));
    names.push_back(name);
  }
  if (auto ok = d.waitset->attachReader(tfr.tf_reader, kTfTag); !ok) return ok;
  if (auto ok = d.waitset->attachReader(tfr.tf_static_reader, kTfStaticTag); !ok) return ok;
  if (tfr.path_reader.get() > 0) {
    if (auto ok = d.waitset->attachReader(tfr.path_reader, kPathTag); !ok) return ok;
  }
  for (std::size_t i = 0; i < readers.size(); ++i) {
    // All attached before any is kept: a robot is added whole or not at all (a reader
    // deleted on the way out leaves the wait set with it).
    if (auto ok = d.waitset->attachReader(readers[i], kCloudTag0 + d.cloud_readers.size() + i);
        !ok) {
      return ok;
    }
  }
  const std::size_t robot = d.robots.size();
  std::lock_guard lock(topics_mutex_);
  for (std::size_t i = 0; i < readers.size(); ++i) {
    d.cloud_topics.push_back(std::move(topics[i]));
    d.cloud_readers.push_back(std::move(readers[i]));
    d.cloud_names.push_back(names[i]);
    d.cloud_frames.emplace_back();
    d.cloud_seq.push_back(0);
    d.cloud_robot.push_back(robot);
  }
  d.robots.push_back(std::move(tfr));
  d.robot_names.push_back(ns);
  state_->tf.emplace_back(options_.tf_buffer_ns);
  return {};
}

Expected<void> Ros2Bridge::announce() {
  // The server as a ROS node with these readers and writers (as rmw_cyclonedds announces its
  // nodes), so ROS tools list it and its topics.
  Dds& d = *dds_;
  std::vector<const dds::Entity*> readers, writers;
  for (const RobotTfReaders& tfr : d.robots) {
    readers.push_back(&tfr.tf_reader);
    readers.push_back(&tfr.tf_static_reader);
    if (tfr.path_reader.get() > 0) readers.push_back(&tfr.path_reader);
  }
  for (const dds::Entity& r : d.cloud_readers) readers.push_back(&r);
  for (const dds::Entity* w :
       {&d.octomap_writer, &d.grid_writer, &d.centers_writer, &d.slice_writer, &d.costmap_writer}) {
    if (w->get() > 0) writers.push_back(w);
  }
  d.node = RosNodeAnnouncement{};  // one announcement writer at a time
  auto node = announceRosNode(*d.participant, options_.gid_layout, "/", options_.node_name, readers,
                              writers);
  if (!node) return std::unexpected(node.error());
  d.node = std::move(*node);
  return {};
}

void Ros2Bridge::discoverRobots() {
  Dds& d = *dds_;
  if (d.publications.get() <= 0) return;
  constexpr std::int32_t kBatch = 64;
  std::vector<std::string> found;
  for (;;) {
    void* samples[kBatch] = {};
    dds_sample_info_t infos[kBatch];
    const dds_return_t n = dds_take(d.publications.get(), samples, infos, kBatch, kBatch);
    if (n <= 0) break;
    for (dds_return_t k = 0; k < n; ++k) {
      const auto* e = static_cast<const dds_builtintopic_endpoint_t*>(samples[k]);
      // Names come off the wire: longer ones than ROS allows (a topic name of at most 255
      // characters after "rt") are not a robot's.
      if (!infos[k].valid_data || e->topic_name == nullptr || e->type_name == nullptr ||
          strnlen(e->topic_name, 259) > 258) {
        continue;
      }
      if (std::strcmp(e->type_name, sensor_msgs_msg_dds__PointCloud2__desc.m_typename) != 0) {
        continue;
      }
      for (const std::string& cloud : options_.clouds) {
        std::string ns = ros2::namespaceOfCloud(e->topic_name, cloud);
        if (!ns.empty() && ros2::matchesGlob(options_.robot_pattern, ns)) {
          found.push_back(std::move(ns));
        }
      }
    }
    dds_return_loan(d.publications.get(), samples, n);
    if (n < kBatch) break;
  }
  bool added = false;
  for (const std::string& ns : found) {
    if (std::find(d.robot_names.begin(), d.robot_names.end(), ns) != d.robot_names.end()) continue;
    if (d.robots.size() >= kMaxRosRobots ||
        d.cloud_readers.size() + options_.clouds.size() > kMaxRosRobots) {
      if (!d.full_logged) {
        spdlog::warn("ros2: robot {} not added: at most {} robots and cloud topics", ns,
                     kMaxRosRobots);
        d.full_logged = true;
      }
      continue;
    }
    if (auto ok = addRobot(ns); !ok) {
      spdlog::warn("ros2: robot {} not added: {}", ns, ok.error().message);
      continue;
    }
    spdlog::info("ros2: robot {} found (ros2.robot_pattern {})", ns, options_.robot_pattern);
    added = true;
  }
  if (added) {
    if (auto ok = announce(); !ok) spdlog::warn("ros2: node announcement: {}", ok.error().message);
  }
}

void Ros2Bridge::start() {
  if (running_.exchange(true)) return;
  thread_ = std::thread([this] { loop(); });
}

void Ros2Bridge::stop() {
  if (!running_.exchange(false)) return;
  dds_->waitset->wake();
  if (thread_.joinable()) thread_.join();
}

void Ros2Bridge::onVersion(const IntegrationResult& result,
                           const std::shared_ptr<const MapView>& view) {
  std::lock_guard lock(versions_mutex_);
  pending_blocks_.insert(pending_blocks_.end(), result.written_blocks.begin(),
                         result.written_blocks.end());
  latest_ = view;
}

Ros2Counters Ros2Bridge::counters() const {
  Ros2Counters c;
  {
    std::lock_guard lock(counters_mutex_);
    c = counters_;
  }
  // Why no clouds may arrive, per topic: DDS's own matched and incompatible-QoS statuses.
  std::lock_guard lock(topics_mutex_);
  for (std::size_t i = 0; i < dds_->cloud_readers.size(); ++i) {
    RosCloudTopicStatus t;
    t.topic = dds_->cloud_names[i];
    dds_subscription_matched_status_t matched{};
    if (dds_get_subscription_matched_status(dds_->cloud_readers[i].get(), &matched) >= 0) {
      t.matched_writers = matched.current_count;
    }
    dds_requested_incompatible_qos_status_t refused{};
    if (dds_get_requested_incompatible_qos_status(dds_->cloud_readers[i].get(), &refused) >= 0) {
      t.incompatible_qos = refused.total_count;
      if (refused.total_count > 0) {
        t.last_incompatible_policy =
            policyName(static_cast<dds_qos_policy_id_t>(refused.last_policy_id));
      }
    }
    c.clouds.push_back(std::move(t));
  }
  return c;
}

void Ros2Bridge::reject(ros2::CloudReject reason) {
  spdlog::debug("ros2: refused a PointCloud2: {}", ros2::cloudRejectName(reason));
  std::lock_guard lock(counters_mutex_);
  ++counters_.rejected;
  ++counters_.rejected_by_reason[static_cast<std::size_t>(reason)];
  counters_.last_reject = std::string(ros2::cloudRejectName(reason));
}

void Ros2Bridge::loop() {
  while (running_.load()) {
    const auto fired = dds_->waitset->wait(std::chrono::milliseconds(20));
    if (!running_.load()) break;
    guarded("ros2 bridge", [&] {
      discoverRobots();
      takeTransforms();  // first: clouds taken below may need them
      for (dds_attach_t tag : fired) {
        if (tag >= kCloudTag0) takeClouds(static_cast<std::size_t>(tag - kCloudTag0));
      }
      const auto now = Clock::now();
      resolveWaiting(now);
      for (std::size_t robot = 0; robot < dds_->robots.size(); ++robot) takePaths(robot);
      if (options_.publish_period_s > 0 && now >= state_->next_publish) {
        // First: a publication that throws waits a period too.
        state_->next_publish = now + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(options_.publish_period_s));
        publishMaps();
      }
    });
  }
}

void Ros2Bridge::takeTransforms() {
  std::uint64_t refused = 0;
  for (std::size_t robot = 0; robot < dds_->robots.size(); ++robot) {
    takeTransforms(robot, refused);
  }
  if (refused > 0) {
    std::lock_guard lock(counters_mutex_);
    counters_.tf_rejected += refused;
  }
}

void Ros2Bridge::takeTransforms(std::size_t robot, std::uint64_t& refused) {
  ros2::TfBuffer& buffer = state_->tf[robot];
  for (const bool is_static : {true, false}) {
    const RobotTfReaders& tfr = dds_->robots[robot];
    const dds::Entity& reader = is_static ? tfr.tf_static_reader : tfr.tf_reader;
    dds::takeAll<tf2_msgs_msg_dds__TFMessage_>(reader, [&](const tf2_msgs_msg_dds__TFMessage_& m) {
      for (std::uint32_t i = 0; i < m.transforms._length; ++i) {
        const auto& ts = m.transforms._buffer[i];
        const auto& tr = ts.transform;
        ros2::TfSample s{
            stampNs(ts.header.stamp),
            {tr.translation.x, tr.translation.y, tr.translation.z},
            Eigen::Quaterniond(tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z)};
        const char* parent = ts.header.frame_id != nullptr ? ts.header.frame_id : "";
        const char* child = ts.child_frame_id != nullptr ? ts.child_frame_id : "";
        if (!buffer.set(parent, child, s, is_static)) ++refused;
      }
    });
  }
}

void Ros2Bridge::takeClouds(std::size_t topic) {
  dds::takeAll<sensor_msgs_msg_dds__PointCloud2_>(
      dds_->cloud_readers[topic], [&](const sensor_msgs_msg_dds__PointCloud2_& m) {
        const std::uint64_t seq = ++dds_->cloud_seq[topic];
        {
          std::lock_guard lock(counters_mutex_);
          ++counters_.received;
        }
        std::vector<ros2::PointFieldView> fields;
        fields.reserve(m.fields._length);
        for (std::uint32_t i = 0; i < m.fields._length; ++i) {
          const auto& f = m.fields._buffer[i];
          fields.push_back({f.name != nullptr ? f.name : "", f.offset, f.datatype, f.count});
        }
        ros2::PointCloud2View v;
        v.height = m.height;
        v.width = m.width;
        v.fields = fields;
        v.is_bigendian = m.is_bigendian;
        v.point_step = m.point_step;
        v.row_step = m.row_step;
        v.data = std::span<const std::uint8_t>(m.data._buffer, m.data._length);
        v.is_dense = m.is_dense;
        auto cloud = ros2::decodePointCloud2(v, options_.max_points);
        if (!cloud) {
          reject(cloud.error());
          return;
        }
        {
          std::lock_guard lock(counters_mutex_);
          counters_.non_finite_points += cloud->non_finite;
        }
        if (cloud->xyz.empty()) {  // every point was NaN
          reject(ros2::CloudReject::kEmpty);
          return;
        }
        Waiting w;
        w.frame = dds::text(m.header.frame_id);
        dds_->cloud_frames[topic] = w.frame;
        w.sensor_id = dds_->cloud_names[topic];
        w.robot = dds_->cloud_robot[topic];
        w.stamp_ns = stampNs(m.header.stamp);
        w.seq = seq;
        w.cloud = std::move(*cloud);
        w.received = Clock::now();
        auto& waiting = state_->waiting;
        waiting.push_back(std::move(w));
        const auto bytesOf = [](const Waiting& c) {
          return (c.cloud.xyz.size() + c.cloud.intensity.size()) * sizeof(float);
        };
        std::size_t bytes = 0;
        for (const Waiting& c : waiting) bytes += bytesOf(c);
        while (waiting.size() > 1 &&
               (waiting.size() > options_.max_waiting || bytes > options_.max_waiting_bytes)) {
          bytes -= bytesOf(waiting.front());
          waiting.pop_front();
          std::lock_guard lock(counters_mutex_);
          ++counters_.no_transform;
        }
      });
}

void Ros2Bridge::resolveWaiting(Clock::time_point now) {
  auto& waiting = state_->waiting;
  // Sensors whose backlog waits for room in the ingest queue: their later clouds wait too (in
  // order), so a burst of clouds a late transform released is integrated, not pushed out.
  std::vector<std::string> held;
  const auto isHeld = [&](const std::string& id) {
    return std::find(held.begin(), held.end(), id) != held.end();
  };
  for (auto it = waiting.begin(); it != waiting.end();) {
    auto T = state_->tf[it->robot].lookup(options_.world_frame, it->frame, it->stamp_ns);
    const bool expired = now - it->received > options_.tf_wait;
    if (!T && !expired && T.error() != ros2::TfFailure::kTooOld) {
      it->waited = true;
      ++it;
      continue;
    }
    if (!T) {
      spdlog::debug("ros2: no transform {} -> {} at {} ns for a cloud on {}: dropped",
                    options_.world_frame, it->frame, it->stamp_ns, it->sensor_id);
      std::lock_guard lock(counters_mutex_);
      ++counters_.no_transform;
    } else {
      if (isHeld(it->sensor_id)) {
        ++it;
        continue;
      }
      RawScan raw;
      raw.sensor_id = it->sensor_id;
      raw.xyz = std::move(it->cloud.xyz);
      raw.intensity = std::move(it->cloud.intensity);
      // The room check sees the cloud's bytes (the queue's byte budget counts them).
      if (it->waited && !ingest_.hasRoomFor(raw)) {
        it->cloud.xyz = std::move(raw.xyz);
        it->cloud.intensity = std::move(raw.intensity);
        held.push_back(it->sensor_id);
        ++it;
        continue;
      }
      raw.seq = it->seq;
      raw.stamp_ns = it->stamp_ns;
      const ros2::ScanPose pose = ros2::toScanPose(*T);
      raw.t_world_sensor = pose.t;
      raw.q_world_sensor = pose.q;
      raw.received = it->received;
      ingest_.submit(std::move(raw));
      std::lock_guard lock(counters_mutex_);
      ++counters_.submitted;
    }
    it = waiting.erase(it);
  }
}

void Ros2Bridge::takePaths(std::size_t robot) {
  const dds::Entity& reader = dds_->robots[robot].path_reader;
  if (reader.get() <= 0) return;
  dds::takeAll<nav_msgs_msg_dds__Path_>(reader, [&](const nav_msgs_msg_dds__Path_& m) {
    std::string frame = dds::text(m.header.frame_id);
    while (!frame.empty() && frame.front() == '/') frame.erase(0, 1);
    const std::string where = "ros2: a corrected path of '" + dds_->robot_names[robot] + "'";
    if (m.poses._length > kMaxCorrectedPoses) {
      (void)ingest_.refuseCorrection(where + " of " + std::to_string(m.poses._length) +
                                     " poses, more than " + std::to_string(kMaxCorrectedPoses));
      return;
    }
    if (frame != options_.world_frame) {
      (void)ingest_.refuseCorrection(where + " in frame '" + frame + "', not ros2.world_frame '" +
                                     options_.world_frame + "'");
      return;
    }
    const ros2::TfBuffer& tf = state_->tf[robot];
    for (std::size_t topic = 0; topic < dds_->cloud_names.size(); ++topic) {
      if (dds_->cloud_robot[topic] != robot || dds_->cloud_frames[topic].empty()) continue;
      PoseCorrection correction{.sensor_id = dds_->cloud_names[topic]};
      std::size_t no_mount = 0;
      for (std::uint32_t i = 0; i < m.poses._length; ++i) {
        const auto& ps = m.poses._buffer[i];
        const std::int64_t stamp = stampNs(ps.header.stamp);
        // The sensor's mount on the base at that stamp (static for a fixed sensor).
        const auto mount = tf.lookup(options_.base_frame, dds_->cloud_frames[topic], stamp);
        if (!mount) {
          ++no_mount;
          continue;
        }
        const auto& p = ps.pose;
        const Eigen::Isometry3d base = ros2::fromScanPose(
            {p.position.x, p.position.y, p.position.z},
            {p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z});
        correction.poses.push_back(toCorrectedPose(stamp, base * *mount));
      }
      if (no_mount > 0) {
        spdlog::warn("{}: {} poses have no transform {} -> {}", where, no_mount,
                     options_.base_frame, dds_->cloud_frames[topic]);
      }
      if (correction.poses.empty()) continue;
      if (auto ok = ingest_.correct(std::move(correction)); !ok) {
        spdlog::warn("{}: {}", where, ok.error().message);
      }
    }
  });
}

}  // namespace densemap::server
