#include "ros2_discovery.hpp"

#include <algorithm>
#include <cstring>
#include <vector>

#include "densemap/wire/topics.hpp"
#include "rmw_dds_common.h"

namespace densemap::server {
namespace {

/// Humble's and Iron's messages differ only in the Gid's size: one filling for both.
template <class Info, class Node, class Gid, class GidSeq, class NodeSeq>
Expected<void> writeAnnouncement(const dds::Entity& writer, const dds_guid_t& participant,
                                 const std::string& node_namespace, const std::string& node_name,
                                 std::span<const dds::Entity* const> readers,
                                 std::span<const dds::Entity* const> writers) {
  const auto gidOf = [](const dds_guid_t& guid) {
    Gid gid{};  // rmw_cyclonedds: the GUID's 16 bytes, the rest zero
    std::memcpy(gid.data, guid.v, std::min(sizeof gid.data, sizeof guid.v));
    return gid;
  };
  const auto gidsOf =
      [&](std::span<const dds::Entity* const> entities) -> Expected<std::vector<Gid>> {
    std::vector<Gid> gids;
    for (const dds::Entity* e : entities) {
      dds_guid_t guid;
      if (auto ok = dds::check(dds_get_guid(e->get(), &guid), "dds_get_guid"); !ok) {
        return std::unexpected(ok.error());
      }
      gids.push_back(gidOf(guid));
    }
    return gids;
  };
  auto reader_gids = gidsOf(readers);
  auto writer_gids = gidsOf(writers);
  if (!reader_gids) return std::unexpected(reader_gids.error());
  if (!writer_gids) return std::unexpected(writer_gids.error());
  Node node{};
  std::strncpy(node.node_namespace, node_namespace.c_str(), sizeof node.node_namespace - 1);
  std::strncpy(node.node_name, node_name.c_str(), sizeof node.node_name - 1);
  node.reader_gid_seq = dds::borrowSequence<GidSeq>(*reader_gids);
  node.writer_gid_seq = dds::borrowSequence<GidSeq>(*writer_gids);
  Info info{};
  info.gid = gidOf(participant);
  info.node_entities_info_seq._maximum = info.node_entities_info_seq._length = 1;
  info.node_entities_info_seq._buffer = &node;
  info.node_entities_info_seq._release = false;
  return dds::write(writer, &info);
}

}  // namespace

Expected<RosGidLayout> parseRosDistro(const std::string& distro) {
  if (distro == "humble") return RosGidLayout::kHumble;
  for (const char* later : {"iron", "jazzy", "kilted", "rolling"}) {
    if (distro == later) return RosGidLayout::kIronAndLater;
  }
  return makeError("ros2.distro: '" + distro +
                   "' is not a ROS 2 distribution densemap knows (humble, iron, jazzy, kilted or "
                   "rolling)");
}

Expected<RosNodeAnnouncement> announceRosNode(const dds::Entity& participant, RosGidLayout layout,
                                              const std::string& node_namespace,
                                              const std::string& node_name,
                                              std::span<const dds::Entity* const> readers,
                                              std::span<const dds::Entity* const> writers) {
  // Iron's layout is generated under a module of its own: published under rmw_dds_common's
  // type name (a copy of its descriptor with that name; the layouts differ in size only).
  static const dds_topic_descriptor_t iron = [] {
    dds_topic_descriptor_t d = densemap_rmw_gid16_msg_dds__ParticipantEntitiesInfo__desc;
    d.m_typename = rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc.m_typename;
    return d;
  }();
  const dds_topic_descriptor_t& descriptor =
      layout == RosGidLayout::kHumble ? rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc
                                      : iron;
  dds_guid_t participant_guid;
  if (auto ok = dds::check(dds_get_guid(participant.get(), &participant_guid), "dds_get_guid");
      !ok) {
    return std::unexpected(ok.error());
  }
  RosNodeAnnouncement a;
  // Not an rt/ topic: ROS's own graph topic (rmw_cyclonedds: avoid_ros_namespace_conventions).
  auto topic = dds::createTopic(participant, descriptor, "ros_discovery_info");
  if (!topic) return std::unexpected(topic.error());
  a.topic = std::move(*topic);
  auto writer = dds::createWriter(participant, a.topic, dds::kLatchedQos);
  if (!writer) return std::unexpected(writer.error());
  a.writer = std::move(*writer);
  const Expected<void> written =
      layout == RosGidLayout::kHumble
          ? writeAnnouncement<rmw_dds_common_msg_dds__ParticipantEntitiesInfo_,
                              rmw_dds_common_msg_dds__NodeEntitiesInfo_,
                              rmw_dds_common_msg_dds__Gid_,
                              dds_sequence_rmw_dds_common_msg_dds__Gid_,
                              dds_sequence_rmw_dds_common_msg_dds__NodeEntitiesInfo_>(
                a.writer, participant_guid, node_namespace, node_name, readers, writers)
          : writeAnnouncement<densemap_rmw_gid16_msg_dds__ParticipantEntitiesInfo_,
                              densemap_rmw_gid16_msg_dds__NodeEntitiesInfo_,
                              densemap_rmw_gid16_msg_dds__Gid_,
                              dds_sequence_densemap_rmw_gid16_msg_dds__Gid_,
                              dds_sequence_densemap_rmw_gid16_msg_dds__NodeEntitiesInfo_>(
                a.writer, participant_guid, node_namespace, node_name, readers, writers);
  if (!written) return std::unexpected(written.error());
  return a;
}

}  // namespace densemap::server
