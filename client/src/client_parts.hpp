#pragma once

// The client's private parts shared by its files: client.cpp (connection, scans, queries,
// commands, status) and client_map.cpp (map versions: events, deltas, fetching the map).
#include <chrono>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "densemap/client/client.hpp"
#include "densemap/wire/dds.hpp"
#include "densemap/wire/topics.hpp"

namespace densemap {
namespace client_detail {

using Clock = std::chrono::steady_clock;

inline void copy3(float (&dst)[3], const Point3f& p) {
  for (int i = 0; i < 3; ++i) dst[i] = p[i];
}

using dds::text;

/// An endpoint DDS Security did not grant is empty: the request fails here, clearly.
inline Expected<void> permitted(const dds::Entity& endpoint, const std::string& what) {
  if (endpoint.get() > 0) return {};
  return makeError(what + ": not allowed by this client's DDS Security permissions");
}

}  // namespace client_detail

/// The client's DDS endpoints.
struct ClientDds {
  dds::Entity participant;
  dds::Topics topics;
  // With DDS Security, an endpoint this identity may not use stays empty (0).
  dds::Entity scan_w, pc_w, pq_w, bq_w, rq_w, dq_w, paq_w, oq_w, dbq_w, cq_w, mq_w;
  dds::Entity pr_r, br_r, rr_r, dr_r, par_r, or_r, dbr_r, cr_r, man_r, delta_r, event_r, st_r;
  // One per reply reader: a request waits for data on its own reader, not by polling.
  std::optional<dds::WaitSet> pr_ws, br_ws, rr_ws, dr_ws, par_ws, or_ws, dbr_ws, cr_ws;
};

/// The client itself; Client forwards to it.
struct Client::Impl {
  using Dds = ClientDds;
  explicit Impl(const ClientOptions& options);
  /// A client of one server (options.instance), its endpoints made.
  static Expected<std::unique_ptr<Impl>> create(const ClientOptions& options);

  Expected<void> waitForServer();
  Expected<void> publishScan(const RawScan& scan);
  Expected<void> publishPoseCorrection(const PoseCorrection& correction);
  Expected<PointQueryAnswer> queryPointsRaw(std::span<const float> xyz);
  Expected<PointQueryAnswer> queryPointsOnce(std::span<const float> xyz);
  Expected<BoxQueryAnswer> queryBox(const Point3f& min, const Point3f& max,
                                    std::uint32_t max_centers);
  Expected<RayQueryAnswer> castRay(const Point3f& origin, const Point3f& direction,
                                   float max_range);
  Expected<DistanceQueryAnswer> queryDistancesOnce(std::span<const float> xyz,
                                                   const DistanceQueryOptions& options);
  /// One request and its reply: the endpoints allowed (DDS Security), `req` written, the reply
  /// to its id awaited; `read(reply, error)` takes a reply the server answered (and may set
  /// `error` for one it cannot use); a refused one is the server's error.
  template <class Reply, class Request, class Read>
  Expected<void> ask(const dds::Entity& writer, const dds::Entity& reader,
                     std::optional<dds::WaitSet>& waitset, const Request& req, const char* what,
                     Read&& read);
  Expected<PathQueryAnswer> checkPath(std::span<const float> xyz, double radius);
  Expected<PathQueryAnswer> checkBoxes(std::span<const OrientedBox> boxes);
  Expected<DistanceBoxAnswer> distanceBox(const Point3f& min, const Point3f& max,
                                          bool unknown_as_occupied);
  /// A command's reply: the detail message and send-map's counts (CommandReply's sent_*).
  struct CommandOutcome {
    std::string detail;
    std::uint64_t sent_version = 0, sent_tiles = 0, sent_cells = 0;
    std::vector<std::pair<std::string, std::int64_t>> sent_stamps;
  };
  Expected<CommandOutcome> commandReply(dds::CommandKind kind, const Point3f& min,
                                        const Point3f& max, const std::string& path);
  Expected<std::string> command(dds::CommandKind kind, const Point3f& min, const Point3f& max,
                                const std::string& path);
  Expected<ServerStatus> status();
  std::size_t pollDeltas(const std::function<void(const DeltaInfo&)>& f);
  std::size_t pollEvents(const std::function<void(const MapEventInfo&)>& f);
  Expected<MapManifestInfo> manifest();
  Expected<MapSnapshot> fetchMap(std::uint64_t min_version);

  ClientOptions options_;
  std::unique_ptr<Dds> dds_;
  std::uint64_t client_id_;
  std::uint64_t next_request_ = 1;
  bool unanswered = false;  // the last request got no reply within the timeout
};

/// Test access (client/testing/densemap/client/testing.hpp).
struct ClientAccess {
  static Client::Impl& impl(Client& client) { return *client.impl_; }
};

}  // namespace densemap
