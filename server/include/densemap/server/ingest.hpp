#pragma once

#include <tbb/task_arena.h>

#include <array>
#include <atomic>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <thread>

#include "densemap/history/scan_history.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/pipeline/engine.hpp"
#include "densemap/planner/distance_field.hpp"
#include "densemap/server/latest_wins_queue.hpp"
#include "densemap/server/sensor_tally.hpp"

namespace densemap::server {

/// The waiting scans of all sensors together: this many times `queue_depth`, beyond which the
/// sensor with the most scans waiting gives up its oldest; one scan per sensor always fits, up
/// to SensorTally::kMaxSensors sensors at once (LatestWinsQueue).
inline constexpr std::size_t kQueueSensorShare = 8;

/// The ingest's settings: the engine's, and how the server runs it.
struct IngestOptions {
  PipelineOptions engine;
  int threads = 2;  // size of the task arena the engine runs in, 1 .. 256
  /// Scans waiting per sensor id (latest wins per sensor: a full sensor's oldest is dropped);
  /// all sensors together kQueueSensorShare times as many, one scan per sensor always fitting.
  /// 4: a 10-Hz sensor's burst after a ~0.4-s stall is absorbed, not dropped. 1 .. 1024.
  std::size_t queue_depth = 4;
  /// Bytes (rawScanBytes) the waiting scans may hold in all: beyond it the sensor with the most
  /// waiting gives up its oldest, else the oldest scan goes (one scan larger than all of it
  /// still waits alone). 0: no byte budget.
  std::size_t queue_budget_bytes = std::size_t{256} << 20;
  /// The distance field planners query (config esdf), updated after every version; none: off.
  std::optional<DistanceFieldOptions> distance_field;
  /// The map's history (config history): the scans integrated, kept so that pose corrections
  /// re-integrate them (log-odds maps without decay); none: off, corrections refused.
  std::optional<HistoryOptions> history;
  /// Threads of the background re-integration, beside the `threads` integrating live scans.
  int history_threads = 1;
};

/// Corrections waiting for the worker at most; more are refused (counted).
inline constexpr std::size_t kMaxPendingCorrections = 16;
/// Scans a replica catching up keeps while it fetches its peer's map (Ingest::beginCatchUp).
inline constexpr std::size_t kMaxCatchUpScans = 4096;

/// The stamp of the last scan integrated per sensor id, in the order the ids first came (a
/// sensor's stamps increase; ROS clouds' seqs are each server's own count, their stamps not).
using SensorStamps = std::vector<std::pair<std::string, std::int64_t>>;

struct PipelineCounters {
  std::uint64_t received = 0;
  std::uint64_t integrated = 0;
  std::uint64_t dropped = 0;
  std::uint64_t rejected = 0;
  std::array<std::uint64_t, kRejectReasonCount> rejected_by_reason{};
  std::string last_reject_reason;
  double latency_p50_ms = 0.0;  // over the last 1024 integrated scans
  double latency_p99_ms = 0.0;
  std::uint64_t evicted_blocks = 0;  // dropped by keep_radius_m / bounds, and their known cells
  std::uint64_t evicted_cells = 0;
  std::uint64_t decayed_cells = 0;      // occupied cells map.decay made unknown
  std::vector<SensorCounters> sensors;  // the same counts per sensor id, with seq gaps
  HistoryStatus history;                // pose corrections (IngestOptions::history)
};

/// The server's ingest (docs/architecture.md): a bounded latest-wins queue in front of the
/// mapping engine (densemap/pipeline/engine.hpp), run one scan at a time by a worker thread
/// inside a task arena of `threads`. Readers get the latest published MapView without waiting
/// for integration. Commands (reset, clear, save...) run on the worker between scans, so the
/// map has one writer. The ingest keeps the counters: received, dropped, rejected (with
/// reasons), per sensor, and the latency of the last 1024 scans.
/// Thread-safety: submit(), view(), command() and counters() from any thread.
class Ingest {
 public:
  using Publisher =
      std::function<void(const IntegrationResult&, const std::shared_ptr<const MapView>&)>;
  using RejectHandler = std::function<void(const RawScan&, const Rejection&)>;
  using Command = Engine::Command;

  /// An ingest over `initial` (or a new empty map) starting at `initial_version`.
  [[nodiscard]] static Expected<std::unique_ptr<Ingest>> create(
      const IngestOptions& options, std::unique_ptr<OccupancyMap> initial = nullptr,
      std::uint64_t initial_version = 0);
  ~Ingest();
  Ingest(const Ingest&) = delete;
  Ingest& operator=(const Ingest&) = delete;

  /// Set before start(). Called on the worker after each scan / state change.
  void setPublisher(Publisher publisher) { publisher_ = std::move(publisher); }
  void setRejectHandler(RejectHandler handler) { on_reject_ = std::move(handler); }

  void start();
  /// Stops taking scans, finishes the one in flight, runs queued commands, joins. Idempotent.
  void stop();

  /// Never blocks. When integration is behind, the oldest queued scan is dropped.
  void submit(RawScan scan);
  /// Whether submit(scan) now would drop no queued scan (a backlog, e.g. clouds that waited
  /// for a late transform, goes in as the queue drains instead).
  [[nodiscard]] bool hasRoomFor(const RawScan& scan) const { return queue_.hasRoomFor(scan); }
  /// Runs `command` on the worker between scans; a non-empty change list publishes a version.
  [[nodiscard]] std::future<Expected<std::string>> command(Command command);
  /// New poses for past scans (IngestOptions::history), from any thread: checked
  /// (checkCorrection) and queued. The worker replaces the stored poses and re-integrates from
  /// the checkpoint before the earliest corrected scan on a background thread, while scans go
  /// on into the live map; once it has caught up, the worker integrates the last few scans
  /// into it and patches the live map to equal it, published as one version. Readers keep
  /// the latest version meanwhile. A correction during a re-integration restarts it from the
  /// earlier checkpoint of the two; a command that changes the map (reset, clear) cancels it
  /// and restarts the history. An error, counted, when the history is off, the correction is
  /// malformed, or kMaxPendingCorrections wait.
  [[nodiscard]] Expected<void> correct(PoseCorrection correction);
  /// Counts a correction refused before correct() could read it (malformed on the wire) and
  /// returns the error.
  Expected<void> refuseCorrection(const std::string& why);

  [[nodiscard]] std::shared_ptr<const MapView> view() const {
    const std::shared_lock lock(engine_swap_);
    return engine_->view();
  }
  /// The latest announced version and the stamp of the last scan integrated per sensor id in
  /// it (at most SensorTally::kMaxSensors ids): what a send-map sends, so that a replica catching
  /// up skips the scans its peer's map holds.
  struct Latest {
    std::shared_ptr<const MapView> view;
    SensorStamps last_stamps;
  };
  [[nodiscard]] Latest latest() const;
  /// Before start(): keeps a copy of every scan integrated from now on (at most
  /// kMaxCatchUpScans) until catchUp().
  void beginCatchUp() { keep_scans_ = true; }
  /// A replica started late (docs/fleet.md, replicas): on the worker, replaces the map by `map`
  /// (a peer's at `version`, holding its scans up to `last_stamps`), integrates the kept scans
  /// it lacks (stamped after the peer's last of their sensor) in arrival order, and publishes the
  /// change as one version. The map then equals the peer's at the same version. An error,
  /// nothing changed, when `version` is not above this map's, or more scans came than were
  /// kept: the scans are then no longer kept. An error starting with kCatchUpGap, the scans
  /// still kept, when the first scan kept of a sensor is stamped after the peer's last: scans
  /// between the two may have reached the peer only; a later fetch of the peer's map holds them.
  static constexpr std::string_view kCatchUpGap = "the peer's map does not reach";
  [[nodiscard]] std::future<Expected<std::string>> catchUp(std::unique_ptr<OccupancyMap> map,
                                                           std::uint64_t version,
                                                           SensorStamps last_stamps);
  /// Runs f(field, view): the distance field and the map version it was updated to, shared with
  /// other readers (it waits for an update under way, a few ms). False, f not run, when the
  /// server keeps no field (config esdf).
  [[nodiscard]] bool hasDistanceField() const { return field_.has_value(); }
  template <class F>
  bool withDistanceField(F&& f) const {
    if (!field_) return false;
    const std::shared_lock lock(field_mutex_);
    f(*field_, *field_view_);
    return true;
  }

  /// What a snapshot saves: the latest view and, for kernel map kinds, the kernel evidence of
  /// the same version (taken on the worker between scans, so the two agree).
  struct SavedState {
    std::shared_ptr<const MapView> view;
    std::optional<kernel::KernelEvidence> kernel;
  };
  /// Waits for the worker (at most one scan) unless the ingest is stopped. Not from a
  /// Command (the worker would wait for itself).
  [[nodiscard]] SavedState savedState();
  /// Before start(): resumes a kernel map kind's evidence from a snapshot. An error
  /// (and nothing changed) for a log-odds kind or another kernel kind's evidence.
  [[nodiscard]] Expected<void> restoreKernelEvidence(const kernel::KernelEvidence& evidence);
  [[nodiscard]] PipelineCounters counters() const;
  [[nodiscard]] const PipelineOptions& options() const { return options_; }

 private:
  Ingest(const IngestOptions& options, std::unique_ptr<Engine> engine);
  void run();
  void runCommands();
  void process(const RawScan& raw);
  /// Counts `raw`'s rejection (in all, by reason, for its sensor) and tells the reject handler.
  void rejected(const RawScan& raw, const Rejection& rejection);
  /// The engine's integration in the arena; anything it throws becomes a kInternal rejection.
  std::expected<IntegrationResult, Rejection> integrate(const RawScan& raw);
  /// Counts an integrated scan (its latency, evictions) and hands the result on.
  void published(IntegrationResult& result);
  // The map's history (ingest_history.cpp), on the worker: after a scan; after a command that
  // changed the map; the corrections waiting; a background re-integration that has caught up.
  void recordScan(const RawScan& raw);
  void restartHistory();
  void applyCorrections();
  void startReintegration(std::uint64_t from_index);
  void finishReintegration();
  void cancelReintegration();
  void historyError(const std::string& message);
  // A replica's catch-up (ingest_catch_up.cpp), on the worker: after a scan; the catch-up
  // waiting.
  void keepForCatchUp(const RawScan& raw);
  void applyCatchUp();

  PipelineOptions options_;
  /// The worker's engine; replaced (catchUp) under engine_swap_, which view() reads under.
  std::unique_ptr<Engine> engine_;
  mutable std::shared_mutex engine_swap_;
  tbb::task_arena arena_;
  std::optional<DistanceField> field_;
  mutable std::shared_mutex field_mutex_;  // the field and field_view_ change together
  std::shared_ptr<const MapView> field_view_;
  LatestWinsQueue<RawScan> queue_;
  Publisher publisher_;
  RejectHandler on_reject_;

  std::mutex commands_mutex_;
  std::vector<std::pair<Command, std::promise<Expected<std::string>>>> commands_;

  mutable std::mutex counters_mutex_;
  PipelineCounters counters_;
  SensorTally sensors_;
  std::vector<double> latencies_;  // ring of the last 1024
  std::size_t latency_next_ = 0;

  std::unique_ptr<ScanHistory> history_;
  tbb::task_arena history_arena_;
  struct Background;  // a re-integration under way: its thread and progress
  std::unique_ptr<Background> background_;
  std::mutex corrections_mutex_;
  std::vector<PoseCorrection> corrections_;  // waiting for the worker
  HistoryStatus history_status_;             // under counters_mutex_

  SensorStamps last_stamps_;  // the worker's
  mutable std::mutex latest_mutex_;
  Latest latest_;  // as of the last announced version
  std::atomic<bool> keep_scans_{false};
  std::vector<RawScan> kept_;  // the worker's (beginCatchUp)
  bool kept_overflow_ = false;
  struct PendingCatchUp {
    std::unique_ptr<OccupancyMap> map;
    std::uint64_t version = 0;
    SensorStamps last_stamps;
    std::promise<Expected<std::string>> done;
  };
  std::mutex catch_up_mutex_;
  std::optional<PendingCatchUp> catch_up_;

  std::atomic<bool> running_{false};
  std::thread worker_;
};

}  // namespace densemap::server
