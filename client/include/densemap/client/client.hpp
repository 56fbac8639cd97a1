#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "densemap/wire/security.hpp"
#include "densemap/wire/status.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/io/sensor_counters.hpp"

namespace densemap {

struct ClientOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
  std::chrono::milliseconds timeout{5000};  // per request, and for discovering the server
  /// Subscribe to map/delta (every changed cell of every version). Off by default: while no
  /// client subscribes, the server builds no deltas. map/events (small) is always read.
  bool subscribe_deltas = false;
  /// DDS Security files of this client's identity (scripts/make-pki.sh); none: plain DDS. With
  /// security, requests its permissions do not grant fail with a "not allowed" error. One
  /// identity per process and domain (Cyclone DDS): a Client with another is refused.
  std::optional<dds::SecurityFiles> security{};
};

struct PointQueryAnswer {
  std::uint64_t map_version = 0;
  std::vector<std::optional<float>> log_odds;
  std::vector<CellState> states;
};

struct BoxQueryAnswer {
  std::uint64_t map_version = 0;
  std::uint64_t occupied = 0, free = 0, unknown = 0;
  std::vector<Point3f> occupied_centers;
};

struct RayQueryAnswer {
  std::uint64_t map_version = 0;
  RayQueryResult ray;
};

struct DeltaInfo {
  std::uint64_t base_version = 0, new_version = 0;
  bool from_scan = false;
  std::string sensor_id;
  std::uint64_t scan_seq = 0;
  CellChanges changes;
};

/// One published map version (densemap/map/events).
struct MapEventInfo {
  std::uint64_t base_version = 0, new_version = 0;
  bool from_scan = false;
  std::string sensor_id;
  std::uint64_t scan_seq = 0;
  std::uint64_t changed_cells = 0;
  std::uint32_t written_blocks = 0;
  double latency_ms = 0.0;  // the server's receive -> published
};

using CommandKind = dds::CommandKind;  // the wire's, shared with the server

/// A densemap-server client over DDS (loopback by default). Requests carry a random client id
/// and an increasing request id; replies are matched on both. Every call has a timeout.
/// Thread-safety: one thread at a time.
class Client {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<Client>> create(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  /// Waits until a server's scan reader and request readers are matched.
  [[nodiscard]] Expected<void> waitForServer();
  [[nodiscard]] Expected<void> publishScan(const RawScan& scan);
  /// A batch of more than dds::kMaxQueryPoints points goes as several requests, one after
  /// another, each answered from one map version; map_version is then the last part's.
  [[nodiscard]] Expected<PointQueryAnswer> queryPoints(const std::vector<Point3f>& points_world);
  /// Sends raw coordinates unchecked (the server validates; split as queryPoints): for tests of
  /// bad input.
  [[nodiscard]] Expected<PointQueryAnswer> queryPointsRaw(const std::vector<float>& xyz);
  /// One request of raw coordinates, unsplit (tests of the server's limit).
  [[nodiscard]] Expected<PointQueryAnswer> queryPointsOnce(std::span<const float> xyz);
  [[nodiscard]] Expected<BoxQueryAnswer> queryBox(const Point3f& min, const Point3f& max,
                                                  std::uint32_t max_centers = 0);
  [[nodiscard]] Expected<RayQueryAnswer> castRay(const Point3f& origin, const Point3f& direction,
                                                 float max_range);
  /// Returns the server's detail message, or its error.
  [[nodiscard]] Expected<std::string> command(CommandKind kind, const Point3f& min = {0, 0, 0},
                                              const Point3f& max = {0, 0, 0},
                                              const std::string& path = {});
  /// The latest status sample (published at 1 Hz, transient-local).
  [[nodiscard]] Expected<ServerStatus> status();
  /// Calls `f` for every map delta received since the last call; returns how many. Needs
  /// ClientOptions::subscribe_deltas (otherwise returns 0).
  std::size_t pollDeltas(const std::function<void(const DeltaInfo&)>& f);
  /// Calls `f` for every map event received since the last call; returns how many.
  std::size_t pollEvents(const std::function<void(const MapEventInfo&)>& f);
  /// Fetches the server's map (what a late joiner does): waits until the manifest reaches
  /// `min_version`, asks for the map (send-map) and rebuilds it from the tiles of one version,
  /// which it returns with the map. Times out only when tiles stop arriving.
  [[nodiscard]] Expected<std::pair<std::unique_ptr<GridMap>, std::uint64_t>> fetchMap(
      std::uint64_t min_version = 0);

 private:
  struct Dds;
  explicit Client(const ClientOptions& options);
  /// A command's reply: the detail message and send-map's counts (CommandReply's sent_*).
  struct CommandOutcome {
    std::string detail;
    std::uint64_t sent_version = 0, sent_tiles = 0, sent_cells = 0;
  };
  [[nodiscard]] Expected<CommandOutcome> commandReply(CommandKind kind, const Point3f& min,
                                                      const Point3f& max, const std::string& path);
  ClientOptions options_;
  std::unique_ptr<Dds> dds_;
  std::uint64_t client_id_;
  std::uint64_t next_request_ = 1;
};

}  // namespace densemap
