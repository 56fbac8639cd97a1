#include "densemap/wire/topics.hpp"

#include <algorithm>
#include <cctype>

#include "densemap_msgs.h"

namespace densemap::dds {

bool isInstanceName(std::string_view name) {
  return !name.empty() && name.size() <= 64 && std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
  });
}

Expected<Topics> Topics::create(const Entity& participant, const std::string& instance) {
  if (!instance.empty() && !isInstanceName(instance)) {
    return makeError("'" + instance +
                     "' is not a server instance name (1 to 64 letters, digits, _)");
  }
  Topics t;
  const struct {
    Entity* topic;
    const dds_topic_descriptor_t* descriptor;
    const char* name;
  } table[] = {
      {&t.scan, &densemap_msgs_Scan_desc, "scan"},
      {&t.pose_correction, &densemap_msgs_PoseCorrection_desc, "pose_correction"},
      {&t.point_request, &densemap_msgs_PointQueryRequest_desc, "query/point/request"},
      {&t.point_reply, &densemap_msgs_PointQueryReply_desc, "query/point/reply"},
      {&t.bbox_request, &densemap_msgs_BboxQueryRequest_desc, "query/bbox/request"},
      {&t.bbox_reply, &densemap_msgs_BboxQueryReply_desc, "query/bbox/reply"},
      {&t.ray_request, &densemap_msgs_RayQueryRequest_desc, "query/ray/request"},
      {&t.ray_reply, &densemap_msgs_RayQueryReply_desc, "query/ray/reply"},
      {&t.distance_request, &densemap_msgs_DistanceQueryRequest_desc, "query/distance/request"},
      {&t.distance_reply, &densemap_msgs_DistanceQueryReply_desc, "query/distance/reply"},
      {&t.path_request, &densemap_msgs_PathQueryRequest_desc, "query/path/request"},
      {&t.path_reply, &densemap_msgs_PathQueryReply_desc, "query/path/reply"},
      {&t.boxes_request, &densemap_msgs_BoxesQueryRequest_desc, "query/boxes/request"},
      {&t.boxes_reply, &densemap_msgs_BoxesQueryReply_desc, "query/boxes/reply"},
      {&t.distance_box_request, &densemap_msgs_DistanceBoxRequest_desc,
       "query/distance_box/request"},
      {&t.distance_box_reply, &densemap_msgs_DistanceBoxReply_desc, "query/distance_box/reply"},
      {&t.command_request, &densemap_msgs_CommandRequest_desc, "cmd/request"},
      {&t.command_reply, &densemap_msgs_CommandReply_desc, "cmd/reply"},
      {&t.map_request, &densemap_msgs_CommandRequest_desc, "map/request"},
      {&t.manifest, &densemap_msgs_MapManifest_desc, "map/manifest"},
      {&t.tiles, &densemap_msgs_MapTile_desc, "map/tiles"},
      {&t.delta, &densemap_msgs_MapDelta_desc, "map/delta"},
      {&t.events, &densemap_msgs_MapEvent_desc, "map/events"},
      {&t.status, &densemap_msgs_Status_desc, "status"},
  };
  for (const auto& row : table) {
    // Every instance reads the same scans and pose corrections.
    const bool shared = row.topic == &t.scan || row.topic == &t.pose_correction;
    auto topic = createTopic(
        participant, *row.descriptor,
        std::string("densemap/") + (instance.empty() || shared ? "" : instance + "/") + row.name);
    // A topic this identity may neither publish nor subscribe stays empty; its readers and
    // writers then fail with the same "not allowed" error.
    if (!topic && isNotAllowedBySecurity(topic.error())) continue;
    if (!topic) return std::unexpected(topic.error());
    *row.topic = std::move(*topic);
  }
  return t;
}

std::string replyPartition(std::uint64_t client_id) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string name = "densemap.reply.";
  for (int shift = 60; shift >= 0; shift -= 4) name += kHex[(client_id >> shift) & 0xF];
  return name;
}

}  // namespace densemap::dds
