#pragma once

// The server as a ROS 2 node: what every rmw implementation writes on
// "ros_discovery_info" so that `ros2 node list` and `ros2 node info` see a node and its topics.
#include <span>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "densemap/wire/dds.hpp"

namespace densemap::server {

/// "humble" -> kHumble; "iron", "jazzy", "kilted", "rolling" -> kIronAndLater.
[[nodiscard]] Expected<RosGidLayout> parseRosDistro(const std::string& distro);

/// The node's announcement: its topic, the writer that keeps it (transient-local, keep-last 1,
/// as rmw_cyclonedds writes it) and nothing else.
struct RosNodeAnnouncement {
  dds::Entity topic, writer;
};

/// Writes one rmw_dds_common ParticipantEntitiesInfo on "ros_discovery_info": the participant's
/// GUID as its gid, one node (`node_namespace`, `node_name`) whose readers and writers are the
/// given entities (their DDS GUIDs, as rmw_cyclonedds takes gids, zero-padded on Humble).
[[nodiscard]] Expected<RosNodeAnnouncement> announceRosNode(
    const dds::Entity& participant, RosGidLayout layout, const std::string& node_namespace,
    const std::string& node_name, std::span<const dds::Entity* const> readers,
    std::span<const dds::Entity* const> writers);

}  // namespace densemap::server
