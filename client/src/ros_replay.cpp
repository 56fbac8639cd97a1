#include "ros_replay.hpp"

#include <chrono>
#include <cstring>
#include <thread>
#include <vector>

#include "densemap/ros2/names.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/topics.hpp"
#include "sensor_msgs.h"
#include "tf2_msgs.h"

namespace densemap::cli {
namespace {

builtin_interfaces_msg_dds__Time_ rosTime(std::int64_t ns) {
  return {static_cast<std::int32_t>(ns / 1'000'000'000),
          static_cast<std::uint32_t>(ns % 1'000'000'000)};
}

Eigen::Isometry3d poseOf(const RawScan& scan) {
  return ros2::fromScanPose(scan.t_world_sensor, scan.q_world_sensor);
}

}  // namespace

struct RosReplayPublisher::Dds {
  dds::Entity participant, cloud_topic, tf_topic, tf_static_topic;
  dds::Entity cloud_writer, tf_writer, tf_static_writer;
};

RosReplayPublisher::RosReplayPublisher(const ros2::ReplayFrames& frames)
    : frames_(frames), dds_(std::make_unique<Dds>()) {}
RosReplayPublisher::~RosReplayPublisher() = default;

Expected<std::unique_ptr<RosReplayPublisher>> RosReplayPublisher::create(
    const dds::ParticipantOptions& participant_options, const std::string& ns,
    const std::string& topic, const ros2::ReplayFrames& frames, bool reliable,
    std::chrono::milliseconds static_delay) {
  std::unique_ptr<RosReplayPublisher> p(new RosReplayPublisher(frames));
  Dds& d = *p->dds_;
  const std::string cloud_name =
      ros2::ddsTopicName(ns.empty() ? topic : ros2::inNamespace(ns, topic));
  if (cloud_name.empty()) return makeError("'" + topic + "' is not a ROS topic name");
  if (!ns.empty() && ros2::inNamespace(ns, "tf").empty()) {
    return makeError("'" + ns + "' is not a ROS namespace");
  }
  auto participant = dds::createParticipant(participant_options);
  if (!participant) return std::unexpected(participant.error());
  d.participant = std::move(*participant);
  auto ct = dds::createTopic(d.participant, sensor_msgs_msg_dds__PointCloud2__desc, cloud_name);
  auto tt = dds::createTopic(d.participant, tf2_msgs_msg_dds__TFMessage__desc,
                             ros2::ddsTopicName(ros2::inNamespace(ns, "tf")));
  auto st = dds::createTopic(d.participant, tf2_msgs_msg_dds__TFMessage__desc,
                             ros2::ddsTopicName(ros2::inNamespace(ns, "tf_static")));
  if (!ct || !tt || !st) return makeError("cannot create the ROS 2 topics");
  d.cloud_topic = std::move(*ct);
  d.tf_topic = std::move(*tt);
  d.tf_static_topic = std::move(*st);
  // A LiDAR driver publishes best effort; the replay can be reliable (the default) so that a
  // reliable reader gets every cloud. /tf: reliable, keep last 100; /tf_static: latched.
  auto cw = dds::createWriter(d.participant, d.cloud_topic, dds::rosCloudQos(reliable));
  auto tw = dds::createWriter(d.participant, d.tf_topic, dds::kTfQos);
  auto sw = dds::createWriter(d.participant, d.tf_static_topic, dds::kLatchedQos);
  if (!cw || !tw || !sw) return makeError("cannot create the ROS 2 writers");
  d.cloud_writer = std::move(*cw);
  d.tf_writer = std::move(*tw);
  d.tf_static_writer = std::move(*sw);
  if (static_delay.count() <= 0) {
    if (auto ok = p->publishStatic(); !ok) return std::unexpected(ok.error());
  } else {
    p->static_due_ = std::chrono::steady_clock::now() + static_delay;
  }
  return p;
}

Expected<void> RosReplayPublisher::publishStatic() {
  // The static transforms, in one latched message as tf2's static broadcaster sends them.
  const ros2::TfSample identity{frames_.stampOf(0), Eigen::Vector3d::Zero(),
                                Eigen::Quaterniond::Identity()};
  ros2::TfSample mount = ros2::sensorMount();
  mount.stamp_ns = frames_.stampOf(0);
  geometry_msgs_msg_dds__TransformStamped_ ts[2] = {};
  const ros2::TfSample* samples[2] = {&identity, &mount};
  const std::string* names[2][2] = {{&frames_.map, &frames_.odom},
                                    {&frames_.base, &frames_.sensor}};
  for (int i = 0; i < 2; ++i) {
    ts[i].header.stamp = rosTime(samples[i]->stamp_ns);
    ts[i].header.frame_id = const_cast<char*>(names[i][0]->c_str());
    ts[i].child_frame_id = const_cast<char*>(names[i][1]->c_str());
    ts[i].transform.translation = {samples[i]->t.x(), samples[i]->t.y(), samples[i]->t.z()};
    ts[i].transform.rotation = {samples[i]->q.x(), samples[i]->q.y(), samples[i]->q.z(),
                                samples[i]->q.w()};
  }
  tf2_msgs_msg_dds__TFMessage_ msg{};
  msg.transforms._length = msg.transforms._maximum = 2;
  msg.transforms._buffer = ts;
  msg.transforms._release = false;
  if (auto ok = dds::write(dds_->tf_static_writer, &msg); !ok) return ok;
  static_sent_ = true;
  return {};
}

Expected<void> RosReplayPublisher::publishStaticWhenDue(bool now) {
  if (static_sent_ || (!now && std::chrono::steady_clock::now() < static_due_)) return {};
  return publishStatic();
}

Expected<void> RosReplayPublisher::waitForReader(int timeout_ms) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
  while (std::chrono::steady_clock::now() < deadline) {
    dds_publication_matched_status_t m{};
    if (dds_get_publication_matched_status(dds_->cloud_writer.get(), &m) >= 0 &&
        m.current_count > 0) {
      return {};
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return makeError("no reader of the cloud topic within " + std::to_string(timeout_ms) +
                   " ms: is densemap-server running with ros2 { enabled: true }?");
}

Expected<void> RosReplayPublisher::publishTf(const ros2::TfSample& s, const std::string& parent,
                                             const std::string& child, bool is_static) {
  geometry_msgs_msg_dds__TransformStamped_ ts{};
  ts.header.stamp = rosTime(s.stamp_ns);
  ts.header.frame_id = const_cast<char*>(parent.c_str());
  ts.child_frame_id = const_cast<char*>(child.c_str());
  ts.transform.translation = {s.t.x(), s.t.y(), s.t.z()};
  ts.transform.rotation = {s.q.x(), s.q.y(), s.q.z(), s.q.w()};
  tf2_msgs_msg_dds__TFMessage_ msg{};
  msg.transforms._length = msg.transforms._maximum = 1;
  msg.transforms._buffer = &ts;
  msg.transforms._release = false;
  return dds::write(is_static ? dds_->tf_static_writer : dds_->tf_writer, &msg);
}

Expected<void> RosReplayPublisher::publish(const RawScan& scan, std::size_t k) {
  if (auto ok = publishStaticWhenDue(false); !ok) return ok;
  if (auto ok = publishTf(ros2::odomToBase(poseOf(scan), frames_.stampOf(k)), frames_.odom,
                          frames_.base, false);
      !ok) {
    return ok;
  }
  const bool with_intensity = !scan.intensity.empty();
  const std::uint32_t step = with_intensity ? 16 : 12;
  const std::size_t n = scan.xyz.size() / 3;
  std::vector<std::uint8_t> data(n * step);
  for (std::size_t i = 0; i < n; ++i) {
    std::memcpy(data.data() + i * step, scan.xyz.data() + 3 * i, 12);
    if (with_intensity) std::memcpy(data.data() + i * step + 12, &scan.intensity[i], 4);
  }
  sensor_msgs_msg_dds__PointField_ fields[4] = {{const_cast<char*>("x"), 0, 7, 1},
                                                {const_cast<char*>("y"), 4, 7, 1},
                                                {const_cast<char*>("z"), 8, 7, 1},
                                                {const_cast<char*>("intensity"), 12, 7, 1}};
  sensor_msgs_msg_dds__PointCloud2_ msg{};
  msg.header.stamp = rosTime(frames_.cloudStamp(k));
  msg.header.frame_id = const_cast<char*>(frames_.sensor.c_str());
  msg.height = 1;
  msg.width = static_cast<std::uint32_t>(n);
  msg.fields._length = msg.fields._maximum = with_intensity ? 4 : 3;
  msg.fields._buffer = fields;
  msg.fields._release = false;
  msg.is_bigendian = false;
  msg.point_step = step;
  msg.row_step = static_cast<std::uint32_t>(data.size());
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(data.size());
  msg.data._buffer = data.data();
  msg.data._release = false;
  msg.is_dense = true;
  return dds::write(dds_->cloud_writer, &msg);
}

Expected<void> RosReplayPublisher::finish(const RawScan& last, std::size_t k_after) {
  // A static delay longer than the replay: the transforms still go out, at its due time.
  if (!static_sent_) {
    std::this_thread::sleep_until(static_due_);
    if (auto ok = publishStaticWhenDue(true); !ok) return ok;
  }
  return publishTf(ros2::odomToBase(poseOf(last), frames_.stampOf(k_after)), frames_.odom,
                   frames_.base, false);
}

}  // namespace densemap::cli
