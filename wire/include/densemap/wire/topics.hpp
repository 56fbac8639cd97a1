#pragma once

#include <cstdint>
#include <string>

#include "densemap/wire/dds.hpp"

namespace densemap::dds {

/// Every densemap topic (docs/operations.md), created once per participant; names and types live
/// here only, for the server and the client alike. With DDS Security, a topic the participant's
/// permissions do not name is left empty (its readers and writers fail as "not allowed").
struct Topics {
  Entity scan;
  /// densemap/pose_correction: read, like the scans, by every instance on the domain.
  Entity pose_correction;
  Entity point_request, point_reply;
  Entity bbox_request, bbox_reply;
  Entity ray_request, ray_reply;
  Entity distance_request, distance_reply;
  Entity path_request, path_reply;
  Entity boxes_request, boxes_reply;
  Entity distance_box_request, distance_box_reply;
  Entity command_request, command_reply;
  /// send-map requests (CommandRequest, kind 3 only; replies on command_reply): a topic of their
  /// own so that DDS Security can grant map fetches without granting reset and clear-bbox.
  Entity map_request;
  Entity manifest, tiles, delta, events, status;

  /// `instance` names one server of several on a domain (replicas, docs/fleet.md): every topic
  /// but the scans' is then densemap/<instance>/..., so each server answers its own clients
  /// while all of them read the same scans. Empty: densemap/... (one server).
  [[nodiscard]] static Expected<Topics> create(const Entity& participant,
                                               const std::string& instance = {});
};

/// Whether `name` may name a server instance: 1 to 64 letters, digits and '_'.
[[nodiscard]] bool isInstanceName(std::string_view name);

/// CommandRequest.kind on the wire (densemap_msgs.idl), for the server and the client alike.
enum class CommandKind : std::int32_t { kReset = 0, kClearBox = 1, kSave = 2, kSendMap = 3 };

/// The most points one PointQueryRequest may carry (3 MB of coordinates, a 1.25 MB reply): the
/// server refuses more, the client library splits a larger batch into requests of this size,
/// sent one after another, so a client has one request's worth of memory in flight at a time.
inline constexpr std::uint32_t kMaxQueryPoints = 250'000;
/// The most sensor ids a send-map reply names with their last integrated scan's stamp.
inline constexpr std::uint32_t kMaxSentStamps = 64;
/// The most vertices one PathQueryRequest may carry.
inline constexpr std::uint32_t kMaxPathVertices = 100'000;
/// The most boxes one BoxesQueryRequest may carry.
inline constexpr std::uint32_t kMaxQueryBoxes = 100'000;
/// The most cells one DistanceBoxReply may carry (16 MiB of distances).
inline constexpr std::uint32_t kMaxDistanceBoxCells = 4'194'304;

/// The partition of one client's reply readers, and of the server's reply writers for that
/// client: a reply reaches its asker only (otherwise every client reads every reply, and many
/// clients' large replies slow each other down).
[[nodiscard]] std::string replyPartition(std::uint64_t client_id);

/// QoS of the request/reply topics (docs/architecture.md: reliable, keep-last 16-64).
inline constexpr QosSpec kRequestQos{.depth = 64};
inline constexpr QosSpec kCommandQos{.depth = 16};
/// Map state for late joiners: reliable, transient-local, keep-last 1 per instance.
inline constexpr QosSpec kLatestStateQos{.depth = 1, .transient_local = true};
/// Map tiles sent on request: reliable, volatile, keep-all (flow-controlled, nothing dropped).
inline constexpr QosSpec kTileQos{.depth = 0};
/// densemap/scan: reliable, keep-last 4 on both sides (the pipeline's queue does the rest).
inline constexpr QosSpec kScanQos{.depth = 4};
/// densemap/pose_correction: reliable, keep-last 16 (each replaces poses; none may be lost).
inline constexpr QosSpec kCorrectionQos{.depth = 16};
/// Per-version streams: the server keeps the last 32 deltas and 64 events for slow readers; a
/// client keeps 256 and 1024 it has not polled yet.
inline constexpr QosSpec kDeltaWriterQos{.depth = 32}, kDeltaReaderQos{.depth = 256};
inline constexpr QosSpec kEventWriterQos{.depth = 64}, kEventReaderQos{.depth = 1024};

/// ROS 2's topics (ROS2.md): clouds keep the last 5 (sensor data QoS; best effort unless the
/// user asks for reliable); /tf reliable, keep-last 100; /tf_static and the published maps
/// latched (reliable, transient-local, keep-last 1 a writer; a /tf_static reader keeps 100,
/// one per broadcaster). All offer XCDR1 only, as rmw_cyclonedds does.
inline constexpr int kRosCloudDepth = 5;
[[nodiscard]] constexpr QosSpec rosCloudQos(bool reliable) {
  return {.reliable = reliable, .depth = kRosCloudDepth, .xcdr1_only = true};
}
inline constexpr QosSpec kTfQos{.depth = 100, .xcdr1_only = true};
/// A robot's corrected path (nav_msgs/Path): reliable, keep-last 4.
inline constexpr QosSpec kRosPathQos{.depth = 4, .xcdr1_only = true};
inline constexpr QosSpec kTfStaticReaderQos{
    .depth = 100, .transient_local = true, .xcdr1_only = true};
inline constexpr QosSpec kLatchedQos{.depth = 1, .transient_local = true, .xcdr1_only = true};

}  // namespace densemap::dds
