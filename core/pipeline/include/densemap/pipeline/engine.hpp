#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/occupancy_decay.hpp"
#include "densemap/pipeline/scan_validator.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace densemap {

struct PipelineOptions {
  Backend backend = Backend::kGrid;
  double resolution_m = 0.2;
  SensorProbabilities sensor;
  double max_range_m = -1.0;  // < 0: unlimited
  IntegrationMethod method = IntegrationMethod::kRaycast;
  UpdateRule rule = UpdateRule::kSet;
  /// The map kind: std::nullopt for the log-odds map (OctoMap's semantics, `method`, `rule`),
  /// or a dense kernel map (AKIMap, BGKOctoMap, BGKOctoMap-L; their published settings). A
  /// kernel map publishes logit(p) = log(alpha / beta) as each cell's log-odds, so queries,
  /// snapshots and updates read it like any map.
  std::optional<kernel::KernelMethod> kernel;
  /// Densify each scan before integration (the upsample stage); std::nullopt: off.
  std::optional<upsample::UpsampleOptions> upsample;
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
  /// with a cold pool the first scans of a 64-beam sensor at 0.1 m spend several times longer
  /// in the apply, and the server's p99 shows it.
  std::size_t reserve_blocks = 16384;
  /// Bounded memory for a long-running server (grid backend, log-odds maps): after each scan,
  /// blocks whose centre is farther than this from the scan's sensor origin are dropped (their
  /// cells become unknown; 0: off) ...
  double keep_radius_m = 0.0;
  /// ... and so are blocks whose centre lies outside this box (min, max; none: no box). A
  /// log-odds map with a box traverses only the rays that reach it (boundsReach): a cell's
  /// value depends only on the rays through it, so the box's cells are those of a map without
  /// it, and servers whose boxes tile space (spatial shards) together hold that map.
  std::optional<std::pair<Point3f, Point3f>> bounds{};
  /// How readers get versions. true: every version is published (MapView::publish) and a
  /// reader holds it while the engine writes the next one, which copies each block it changes
  /// (the server: queries never wait). false: the map is written in place and view() is valid
  /// only until the next write (MapView::advanceLive): for a caller whose readers and writer
  /// take turns (the in-process Mapper's default), about a fifth less time a scan.
  bool versioned_views = true;
  /// A map that forgets what moved (OccupancyDecay): occupied cells not hit for a while decay
  /// to unknown. std::nullopt (default): off, and the map is OctoMap's exactly. Log-odds maps
  /// on the grid backend.
  std::optional<DecayOptions> decay;
};

/// Whether the segment from `from` to `to` meets the box [lo, hi] (closed; slab test).
[[nodiscard]] bool segmentMeetsBox(const Point3f& from, const Point3f& to, const Point3f& lo,
                                   const Point3f& hi);

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
  DecayStats decayed;  // cells that decayed with this scan (PipelineOptions::decay)
  /// Scans (Engine::integrate): the points as integrated, in the world frame, and the sensor's
  /// pose, for live viewers of the latest scan (the server's Foxglove endpoint).
  std::shared_ptr<const PointCloud> points_world;
  Transform T_world_sensor = Transform::Identity();
};

/// The longest ray a map takes, m (checkMapOptions).
inline constexpr double kMaxRangeM = 2000.0;

/// The one rule for a map's options from outside (the server's config, the Mapper's options):
/// resolution in [0.001, 100] m; max range < 0 (unlimited) or in (0, 2000] m and at most 65,536
/// cells per ray; keep radius finite and >= 0; bounds finite with min < max on every axis;
/// 0 < clamp_min < 0.5, prob_miss < 0.5 < prob_hit < 1, 0.5 < clamp_max < 1; eviction on the
/// grid backend only. Errors name the field (resolution_m, max_range_m, keep_radius_m, bounds,
/// sensor); decay (checkDecayOptions) on a log-odds map on the grid backend (decay).
[[nodiscard]] Expected<void> checkMapOptions(const PipelineOptions& options);

class MapKind;  // the map kind the engine integrates into (src/map_kind.hpp)

/// The mapping engine (docs/architecture.md), one scan at a time on the caller's thread (its
/// parallel stages use the caller's TBB arena): validate -> transform (pose, [upsample]) ->
/// integrate into the map kind -> evict -> publish a MapView. It owns the map and no thread,
/// queue or counter: the server's ingest (densemap/server/ingest.hpp) runs it behind a queue.
/// Readers get the latest published view from any thread (view()); everything else from one
/// thread at a time.
class Engine {
 public:
  /// Runs on the engine's thread with the map and a change list to fill; returns a message or
  /// an error.
  using Command = std::function<Expected<std::string>(OccupancyMap&, CellChanges&)>;

  /// An engine over `initial` (or a new empty map) starting at `initial_version`; the options'
  /// threads and queue fields are not read here.
  [[nodiscard]] static Expected<std::unique_ptr<Engine>> create(
      const PipelineOptions& options, std::unique_ptr<OccupancyMap> initial = nullptr,
      std::uint64_t initial_version = 0);
  ~Engine();
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  /// One scan through every stage: a published version and its result, or why it was
  /// rejected (the map unchanged). The result names the scan (sensor, seq, stamp); its
  /// latency is the caller's to fill.
  [[nodiscard]] std::expected<IntegrationResult, Rejection> integrate(const RawScan& raw);
  /// One scan already in the world frame: its points and the sensor origin (metres), checked
  /// (checkWorldScan) and integrated as they are, so the map equals what OctoMap's
  /// insertPointCloud(points, origin) builds. Upsampling, which needs the sensor frame, does
  /// not apply. Evicted and published as integrate(RawScan). `stamp_ns` is the scan's time
  /// for decay (none: the time it is integrated).
  [[nodiscard]] std::expected<IntegrationResult, Rejection> integrateWorld(
      const PointCloud& points_world, const Point3f& origin_world,
      std::optional<std::int64_t> stamp_ns = std::nullopt);
  /// Runs `command` on the map; a non-empty change list publishes a version (`result`).
  [[nodiscard]] Expected<std::string> command(const Command& command, IntegrationResult& result);
  /// Integrates a synthetic fan into scratch buffers (PipelineOptions::warm_up).
  void warmUp();

  /// The latest version (options().versioned_views false: valid until the next write).
  [[nodiscard]] std::shared_ptr<const MapView> view() const { return view_.load(); }
  /// A kernel map kind's evidence of the latest version (snapshots); none for log-odds.
  [[nodiscard]] std::optional<kernel::KernelEvidence> evidence() const;
  /// Resumes a kernel map kind's evidence from a snapshot. An error (and nothing
  /// changed) for a log-odds kind or another kernel kind's evidence.
  [[nodiscard]] Expected<void> restore(const kernel::KernelEvidence& evidence);
  [[nodiscard]] const PipelineOptions& options() const { return options_; }

 private:
  Engine(const PipelineOptions& options, std::unique_ptr<OccupancyMap> map, std::uint64_t version);
  /// The scan's points in the world frame (densified first when upsampling is on).
  void transform(Scan& scan, PointCloud& points_world, Point3f& origin_world) const;
  /// Decays, integrates, evicts and publishes (the stages after transform()); `now_ns` is the
  /// decay clock's time of the scan.
  IntegrationResult integratePoints(const PointCloud& points_world, const Point3f& origin_world,
                                    std::int64_t now_ns);
  /// Before a scan at `now_ns`: the decay steps due (PipelineOptions::decay) ...
  void decayBefore(std::int64_t now_ns, IntegrationResult& result, CellChanges* changes);
  /// ... and after it: its hit cells wait again.
  void observeHits(std::int64_t now_ns);
  /// Drops the blocks keep_radius_m / bounds leave out, after a scan from `origin`.
  void evict(const Point3f& origin, IntegrationResult& result, CellChanges* changes);
  void publish(IntegrationResult& result);
  /// The points whose rays reach the cells `bounds` keeps (all when there is no box or the kind
  /// is a kernel map, whose cells depend on the hits around them): `points_world` itself or
  /// rays_in_bounds_.
  const PointCloud& raysReachingBounds(const PointCloud& points_world, const Point3f& origin);

  PipelineOptions options_;
  /// The map kind (log-odds or a kernel map) behind one interface (map_kind.hpp).
  std::unique_ptr<MapKind> kind_;
  std::atomic<std::shared_ptr<const MapView>> view_;
  std::unique_ptr<OccupancyDecay> decay_;  // PipelineOptions::decay; null when off
  std::vector<VoxelKey> hits_;             // observeHits' scratch
  PointCloud rays_in_bounds_;              // raysReachingBounds' scratch
};

}  // namespace densemap
