#pragma once

#include <atomic>
#include <filesystem>
#include <memory>
#include <optional>
#include <string_view>
#include <thread>

#include "densemap/wire/dds.hpp"
#include "densemap/server/foxglove_options.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/ros2_bridge.hpp"

namespace densemap::server {

class RequestStats;
class RequestTasks;
class SnapshotSaver;
class ReplyWriters;
class QueryRoom;
class CommandRoom;
class Publisher;
class StatusRoom;
class FoxgloveRoom;

struct ServiceOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
  /// dds.instance: this server's name among replicas on the domain ("": the only server).
  std::string instance;
  std::optional<dds::SecurityFiles> security;  // DDS Security; none: plain DDS
  std::filesystem::path snapshot_path;         // empty: no snapshots
  int snapshot_keep = 3;                       // files kept: path, path.1, ... (core/store)
  std::filesystem::path export_dir;  // where `save --path NAME` writes (exportDirectory())
  double autosave_period_s = 0.0;    // 0: off
  std::size_t max_query_cells = 50'000'000;
  /// Memory for query requests in flight (their copies and replies); beyond it new requests
  /// wait in DDS, and one larger than all of it is refused.
  std::size_t request_budget_bytes = std::size_t{256} << 20;
  int query_threads = 2;            // the query task arena: requests are answered in parallel
  std::optional<Ros2Options> ros2;  // the ROS 2 face (Ros2Bridge); none: off
  std::optional<FoxgloveOptions> foxglove;  // the Foxglove WebSocket endpoint; none: off
  /// How long create() listens for another server's status writer before it creates the
  /// endpoints clients match (docs/security.md: two servers on one domain are detected).
  std::chrono::milliseconds alone_discovery{1000};
};

/// densemap-server's DDS face (docs/operations.md): the endpoints, three threads, and rooms of
/// one job each in server/src (replies, request_tasks, query_room, command_room, publisher,
/// status_room, snapshot_saver):
/// - ingest: only takes scans and submits them to the pipeline;
/// - service: takes requests; point/bbox/ray queries run as tasks in the query arena (one slow
///   bbox does not hold up point queries), each answered from the latest published version;
///   commands run here (they wait for the pipeline's worker);
/// - publish: per version, a map/delta (only while a reader is matched; diffed from the
///   versions' written blocks, never the whole map); status and manifest at 1 Hz; autosave.
/// A late joiner asks for the map (send-map): a query task writes one version's tiles to it
/// (keep-all, flow-controlled), so no copy of the map waits in DDS for readers that may come.
/// The pipeline's worker only writes a small map/events sample and hands the version over.
class MapService {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<MapService>> create(Ingest& ingest,
                                                                    const ServiceOptions& options);
  ~MapService();
  MapService(const MapService&) = delete;
  MapService& operator=(const MapService&) = delete;

  void start();
  /// Stops taking scans and requests; finishes queries in flight; joins the threads. Idempotent.
  void stop();
  /// When the publish thread last went round its loop (at least once a second while it runs):
  /// the liveness the systemd watchdog reports.
  [[nodiscard]] std::chrono::steady_clock::time_point heartbeat() const {
    return std::chrono::steady_clock::time_point(
        std::chrono::steady_clock::duration(heartbeat_.load()));
  }
  /// The start of create()'s error when another server runs on the domain.
  static constexpr std::string_view kAnotherServer = "another densemap-server";
  /// Saves the latest map version to `file` (or the configured snapshot path). A failure is
  /// counted in the status (snapshot_failures, last_snapshot_error).
  [[nodiscard]] Expected<std::size_t> save(const std::filesystem::path& file = {});

 private:
  struct Dds;
  MapService(Ingest& ingest, const ServiceOptions& options);
  /// The rooms, once the DDS endpoints exist (create()).
  void makeRooms();
  void ingestLoop();
  void serviceLoop();
  void publishLoop();
  /// Fails when another densemap-server's status writer is discovered on the domain within
  /// `discovery` (docs/security.md: two servers on one domain are detected, not merged).
  [[nodiscard]] Expected<void> checkAlone(std::chrono::milliseconds discovery) const;

  Ingest& ingest_;
  ServiceOptions options_;
  std::unique_ptr<Dds> dds_;  // before the rooms: they hold its endpoints
  std::unique_ptr<Ros2Bridge> ros2_;
  std::unique_ptr<FoxgloveRoom> foxglove_;  // the Foxglove endpoint's own thread
  // Rooms of one job each (server/src): shared request counters, the request task arena with
  // its memory budget, snapshots; the per-client reply writers; queries; commands; publishing
  // of versions; status.
  std::unique_ptr<RequestStats> stats_;
  std::unique_ptr<RequestTasks> tasks_;
  std::unique_ptr<SnapshotSaver> saver_;
  std::unique_ptr<ReplyWriters> replies_;
  std::unique_ptr<QueryRoom> queries_;
  std::unique_ptr<CommandRoom> commands_;
  std::unique_ptr<Publisher> publisher_;
  std::unique_ptr<StatusRoom> status_;
  std::atomic<bool> running_{false};
  std::atomic<std::chrono::steady_clock::rep> heartbeat_{0};
  std::thread scan_taker_;  // ingestLoop: takes scans off DDS
  std::thread service_;
  std::thread publish_;
};

}  // namespace densemap::server
