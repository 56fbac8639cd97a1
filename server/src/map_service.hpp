#pragma once

#include <atomic>
#include <filesystem>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include "densemap/dds/dds.hpp"
#include "densemap/pipeline/pipeline.hpp"

namespace densemap::server {

struct ServiceOptions {
  std::uint32_t domain_id = 0;
  std::string network_interface = "lo";
  std::filesystem::path snapshot_path;  // empty: no snapshots
  double autosave_period_s = 0.0;       // 0: off
  std::size_t max_query_cells = 50'000'000;
};

/// densemap-server's DDS face (DESIGN.md topics): an ingest thread that only takes scans and
/// submits them to the pipeline; a service thread that answers queries and commands from the
/// latest published map version, publishes status at 1 Hz, map tiles + manifest (transient-
/// local, for late joiners) at most once a second, and autosaves. Per-scan deltas are
/// published by the pipeline's publish stage.
class MapService {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<MapService>> create(Pipeline& pipeline,
                                                                    const ServiceOptions& options);
  ~MapService();
  MapService(const MapService&) = delete;
  MapService& operator=(const MapService&) = delete;

  void start();
  /// Stops taking scans and requests; joins the threads. Idempotent.
  void stop();
  /// Saves the latest map version to `file` (or the configured snapshot path).
  [[nodiscard]] Expected<std::size_t> save(const std::filesystem::path& file = {});

 private:
  struct Dds;
  MapService(Pipeline& pipeline, const ServiceOptions& options);
  void ingestLoop();
  void serviceLoop();
  void onIntegrated(const IntegrationResult& result, const std::shared_ptr<const MapView>& view);
  void answerPointQueries();
  void answerBboxQueries();
  void answerRayQueries();
  void answerCommands();
  void publishStatus();
  void publishTiles();
  void noteBadRequest(const std::string& error);

  Pipeline& pipeline_;
  ServiceOptions options_;
  std::unique_ptr<Dds> dds_;
  std::atomic<bool> running_{false};
  std::thread ingest_;
  std::thread service_;
  std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();

  std::mutex dirty_mutex_;
  std::set<std::uint64_t> dirty_tiles_;
  std::set<std::uint64_t> known_tiles_;  // service thread only
  bool manifest_published_ = false;
  std::atomic<std::uint64_t> queries_answered_{0};
  std::atomic<std::uint64_t> queries_rejected_{0};
  std::mutex error_mutex_;
  std::string last_query_error_;
};

/// Tiles are cubes of 32^3 cells; a tile's id packs the upper key bits.
[[nodiscard]] std::uint64_t tileOf(const VoxelKey& k);

}  // namespace densemap::server
