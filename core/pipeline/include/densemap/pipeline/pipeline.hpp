#pragma once

#include <tbb/task_arena.h>

#include <array>
#include <atomic>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <thread>

#include "densemap/io/raw_scan.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/pipeline/latest_wins_queue.hpp"
#include "densemap/pipeline/scan_validator.hpp"
#include "densemap/pipeline/sensor_tally.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace densemap {

/// The waiting scans of all sensors together: this many times `queue_depth`, beyond which the
/// sensor with the most scans waiting gives up its oldest; one scan per sensor always fits, up
/// to SensorTally::kMaxSensors sensors at once (LatestWinsQueue).
inline constexpr std::size_t kQueueSensorShare = 8;

struct PipelineOptions {
  Backend backend = Backend::kGrid;
  double resolution_m = 0.2;
  SensorProbabilities sensor;
  double max_range_m = -1.0;  // < 0: unlimited
  IntegrationMethod method = IntegrationMethod::kSuperRayCulling;
  UpdateRule rule = UpdateRule::kSet;
  /// The map kind: std::nullopt for the log-odds map (OctoMap's semantics, `method`, `rule`),
  /// or a dense kernel map (AKIMap, BGKOctoMap, BGKOctoMap-L; their published settings). A
  /// kernel map publishes logit(p) = log(alpha / beta) as each cell's log-odds, so queries,
  /// snapshots and updates read it like any map.
  std::optional<kernel::KernelMethod> kernel;
  /// Densify each scan before integration (issue 6's upsample stage); std::nullopt: off.
  std::optional<upsample::UpsampleOptions> upsample;
  int threads = 2;  // size of the task arena the pipeline owns
  /// Scans waiting per sensor id (latest wins per sensor: a full sensor's oldest is dropped);
  /// all sensors together kQueueSensorShare times as many, one scan per sensor always fitting.
  std::size_t queue_depth = 2;
  /// Bytes (rawScanBytes) the waiting scans may hold in all: beyond it the sensor with the most
  /// waiting gives up its oldest, else the oldest scan goes (one scan larger than all of it
  /// still waits alone). 0: no byte budget.
  std::size_t queue_budget_bytes = std::size_t{256} << 20;
  ScanLimits limits;
  /// Fill IntegrationResult::changes for scans (cell by cell: costs O(changed cells) per
  /// scan). Off by default: readers diff published versions by their written blocks instead.
  bool collect_changes = false;
  /// At creation, integrate a synthetic full-range fan (16 x 256 rays) into a scratch map, so
  /// the integrator's per-worker buffers are allocated and faulted in before the first real
  /// scan instead of during it. Off by default: it lowers the first scans' latency (p99) but
  /// keeps buffers sized for the fan (about 230 MB at 0.1 m / 80 m) for the process's life.
  bool warm_up = false;
  /// Blocks allocated and faulted in at creation in the map's node pool (2.2 KB each; they
  /// become map blocks or copy-on-write copies as scans arrive). Page faults are slow on VMs:
  /// on the 64-beam simulation at 0.1 m the first two scans took 60-76 ms to apply with a cold
  /// pool and 5-10 ms with 16384 reserved, and the server's p99 fell from about 220 to 115-145 ms.
  std::size_t reserve_blocks = 16384;
  /// Bounded memory for a long-running server (grid backend, log-odds maps): after each scan,
  /// blocks whose centre is farther than this from the scan's sensor origin are dropped (their
  /// cells become unknown; 0: off) ...
  double keep_radius_m = 0.0;
  /// ... and so are blocks whose centre lies outside this box (min, max; none: no box).
  std::optional<std::pair<Point3f, Point3f>> bounds{};
};

/// What the publish stage hands on for every integrated scan.
struct IntegrationResult {
  bool from_scan = false;  // false: a command changed the map
  std::string sensor_id;
  std::uint64_t scan_seq = 0;
  std::int64_t stamp_ns = 0;
  std::uint64_t base_version = 0;
  std::uint64_t new_version = 0;
  /// The blocks this version wrote (cells changed in each, or none when written and restored).
  std::vector<std::uint64_t> written_blocks;
  /// The changed cells: always for commands, for scans when `collect_changes` is set.
  CellChanges changes;
  ScanStats stats;
  double latency_ms = 0.0;         // received -> published
  std::size_t evicted_blocks = 0;  // dropped by keep_radius_m / bounds with this scan
  std::size_t evicted_cells = 0;
};

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
  std::vector<SensorCounters> sensors;  // the same counts per sensor id, with seq gaps
};

class MapKind;  // the map kind the pipeline integrates into (src/map_kind.hpp)

/// The ingest pipeline (DESIGN.md data flow): a bounded latest-wins queue feeding a TBB flow
/// graph validate -> transform -> integrate -> publish, run one scan at a time by a worker
/// thread inside the task arena the pipeline owns. Readers get the latest published MapView
/// without waiting for integration: a view reads the map's own versioned blocks, so a scan's
/// publish costs O(changed blocks) and the map is held once (a second, mirrored GridMap only
/// for the octree backend). Commands (reset, clear, save...) run on the worker between
/// scans, so the map has one writer.
/// Thread-safety: submit(), view(), command() and counters() from any thread.
class Pipeline {
 public:
  using Publisher =
      std::function<void(const IntegrationResult&, const std::shared_ptr<const MapView>&)>;
  using RejectHandler = std::function<void(const RawScan&, const Rejection&)>;
  /// Runs on the worker with the map and a change list to fill; returns a message or an error.
  using Command = std::function<Expected<std::string>(OccupancyMap&, CellChanges&)>;

  /// A pipeline over `initial` (or a new empty map) starting at `initial_version`.
  [[nodiscard]] static Expected<std::unique_ptr<Pipeline>> create(
      const PipelineOptions& options, std::unique_ptr<OccupancyMap> initial = nullptr,
      std::uint64_t initial_version = 0);
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  /// Set before start(). Called on the worker after each scan / state change.
  void setPublisher(Publisher publisher) { publisher_ = std::move(publisher); }
  void setRejectHandler(RejectHandler handler) { on_reject_ = std::move(handler); }

  void start();
  /// Stops taking scans, finishes the one in flight, runs queued commands, joins. Idempotent.
  void stop();

  /// Never blocks. When integration is behind, the oldest queued scan is dropped.
  void submit(RawScan scan);
  /// Runs `command` on the worker between scans; a non-empty change list publishes a version.
  [[nodiscard]] std::future<Expected<std::string>> command(Command command);

  [[nodiscard]] std::shared_ptr<const MapView> view() const { return view_.load(); }

  /// What a snapshot saves: the latest view and, for kernel map kinds, the kernel evidence of
  /// the same version (taken on the worker between scans, so the two agree).
  struct SavedState {
    std::shared_ptr<const MapView> view;
    std::optional<kernel::KernelEvidence> kernel;
  };
  /// Waits for the worker (at most one scan) unless the pipeline is stopped. Not from a
  /// Command (the worker would wait for itself).
  [[nodiscard]] SavedState savedState();
  /// Before start(): resumes a kernel map kind's evidence from a snapshot (issue 29). An error
  /// (and nothing changed) for a log-odds kind or another kernel kind's evidence.
  [[nodiscard]] Expected<void> restoreKernelEvidence(const kernel::KernelEvidence& evidence);
  [[nodiscard]] PipelineCounters counters() const;
  [[nodiscard]] const PipelineOptions& options() const { return options_; }

 private:
  struct Job;
  struct Graph;
  Pipeline(const PipelineOptions& options, std::unique_ptr<OccupancyMap> map,
           std::uint64_t version);
  void run();
  void runCommands();
  void process(RawScan raw);
  void publish(IntegrationResult& result);
  /// Drops the blocks keep_radius_m / bounds leave out, after a scan from `origin`.
  void evict(const Point3f& origin, IntegrationResult& result, CellChanges* changes);

  PipelineOptions options_;
  /// The map kind (log-odds or a kernel map) behind one interface (map_kind.hpp).
  std::unique_ptr<MapKind> kind_;
  tbb::task_arena arena_;
  std::unique_ptr<Graph> graph_;
  LatestWinsQueue<RawScan> queue_;
  std::atomic<std::shared_ptr<const MapView>> view_;
  Publisher publisher_;
  RejectHandler on_reject_;

  std::mutex commands_mutex_;
  std::vector<std::pair<Command, std::promise<Expected<std::string>>>> commands_;

  mutable std::mutex counters_mutex_;
  PipelineCounters counters_;
  SensorTally sensors_;
  std::vector<double> latencies_;  // ring of the last 1024
  std::size_t latency_next_ = 0;

  std::atomic<bool> running_{false};
  std::thread worker_;
};

}  // namespace densemap
