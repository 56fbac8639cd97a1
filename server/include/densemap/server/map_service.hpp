#pragma once

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <atomic>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "densemap/dds/dds.hpp"
#include "densemap/pipeline/pipeline.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "densemap_msgs.h"

namespace densemap::server {

struct ServiceOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
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
  /// How long create() listens for another server's status writer before it creates the
  /// endpoints clients match (DESIGN.md: two servers on one domain are detected).
  std::chrono::milliseconds alone_discovery{1000};
};

/// What send-map wrote: its command reply's counts (a fetch waits for that many tiles and
/// cells of that version).
struct SentMap {
  std::uint64_t version = 0, tiles = 0, cells = 0;
};

/// densemap-server's DDS face (DESIGN.md topics), three threads and a task arena:
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
  [[nodiscard]] static Expected<std::unique_ptr<MapService>> create(Pipeline& pipeline,
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
  struct Version {  // a published version handed to the publish thread
    IntegrationResult result;
    std::shared_ptr<const MapView> view;
  };
  MapService(Pipeline& pipeline, const ServiceOptions& options);
  void ingestLoop();
  void serviceLoop();
  void publishLoop();
  void onIntegrated(const IntegrationResult& result, const std::shared_ptr<const MapView>& view);
  /// Runs `task` in the query arena, counted in queries_in_flight_ until it ends.
  /// Runs a request's task in the query arena; `bytes` is charged to the request budget while
  /// it runs.
  void runTask(std::function<void()> task, std::size_t bytes = 0);
  /// The memory a point request of `coordinates` floats holds while it is answered.
  [[nodiscard]] static std::size_t pointRequestBytes(std::size_t coordinates);
  void takeQueries();
  void answerCommands();
  void replyCommand(const densemap_msgs_RequestId& id, const Expected<std::string>& outcome,
                    const SentMap& sent = {});
  [[nodiscard]] Expected<std::size_t> saveUncounted(const std::filesystem::path& file);
  /// Fails when another densemap-server's status writer is discovered on the domain within
  /// `discovery` (DESIGN.md: two servers on one domain are detected, not merged).
  [[nodiscard]] Expected<void> checkAlone(std::chrono::milliseconds discovery) const;
  /// Participants other than this one that write densemap/status (other servers).
  [[nodiscard]] std::vector<std::string> otherServers() const;
  /// The reply topics (replyWriter).
  enum class ReplyTopic { kPoint, kBbox, kRay, kCommand };
  /// The writer of `topic`'s replies to client `client_id`: in that client's partition
  /// (dds::replyPartition), so only its readers receive them; made at its first request on
  /// that topic, the most recently used kept (a task holding one keeps it alive). Null when DDS
  /// refuses it. Thread-safe.
  std::shared_ptr<const dds::Entity> replyWriter(ReplyTopic topic, std::uint64_t client_id);
  /// Waits until `writer` has matched a reader of `asker`, at most what is left of kAskerWait
  /// (in the .cpp) since the asker's first request. Thread-safe.
  void awaitAsker(const dds::Entity& writer, const std::optional<dds_guid_t>& asker);
  void publishDeltas(std::deque<Version>& versions);
  void publishStatus();
  void publishManifest();
  /// Writes the latest version's tiles for `request` (send-map); returns what it wrote.
  Expected<SentMap> sendMap(const densemap_msgs_RequestId& request);
  void noteBadRequest(const std::string& error);

  Pipeline& pipeline_;
  ServiceOptions options_;
  std::unique_ptr<Dds> dds_;
  std::unique_ptr<Ros2Bridge> ros2_;
  std::atomic<bool> running_{false};
  std::atomic<std::chrono::steady_clock::rep> heartbeat_{0};
  std::thread ingest_;
  std::thread service_;
  std::thread publish_;
  std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();

  tbb::task_arena query_arena_;
  tbb::task_group queries_;
  std::atomic<int> queries_in_flight_{0};
  std::atomic<std::size_t> request_bytes_{0};      // charged to options_.request_budget_bytes
  std::atomic<std::size_t> served_since_trim_{0};  // request bytes answered since the last trim
  struct CachedReplyWriter {
    std::shared_ptr<const dds::Entity> writer;
    std::uint64_t last_used = 0;
  };
  std::mutex reply_writers_mutex_;
  std::map<std::pair<std::uint64_t, int>, CachedReplyWriter> reply_writers_;  // (client, topic)
  std::uint64_t reply_writer_uses_ = 0;
  std::mutex askers_mutex_;
  std::unordered_set<std::string> askers_matched_;  // "writer:participant" seen matched
  std::unordered_map<std::string, std::chrono::steady_clock::time_point> asker_first_seen_;

  std::mutex versions_mutex_;
  std::condition_variable versions_cv_;
  std::deque<Version> versions_;
  // Publish thread only:
  std::shared_ptr<const MapView> delta_base_;  // the last version a delta went out for

  std::atomic<std::uint64_t> queries_answered_{0};
  std::atomic<std::uint64_t> queries_rejected_{0};
  std::mutex error_mutex_;
  std::mutex save_mutex_;  // one snapshot rotation at a time (command save, autosave, shutdown)
  std::atomic<std::uint64_t> snapshot_failures_{0};
  std::chrono::steady_clock::time_point next_alone_check_{};  // publish thread only
  std::string last_snapshot_error_;                           // error_mutex_
  std::string last_query_error_;
};

}  // namespace densemap::server
