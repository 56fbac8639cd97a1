#pragma once

#include <Eigen/Geometry>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/map/decay_options.hpp"
#include "densemap/map/sensor_model.hpp"
#include "densemap/planner/planner_types.hpp"
#include "densemap/query/cell_state.hpp"

namespace densemap {

/// How a Mapper builds its map: the server's `map` and `pipeline` settings
/// (docs/configuration.md), as plain values.
struct MapperOptions {
  /// Voxel edge, metres, 0.001 .. 100.
  double resolution_m = 0.2;
  /// Rays longer than this are cut and their end is not occupied; < 0: unlimited (OctoMap's
  /// convention), else at most 2,000 m and 65,536 cells per ray.
  double max_range_m = -1.0;
  /// "log_odds" (OctoMap's map, exactly), or a dense kernel map: "akimap_rays", "akimap",
  /// "bgk", "bgkl" (docs/dense-maps.md).
  std::string kind = "log_odds";
  /// "grid" (sparse 8^3 blocks, fast) or "octree" (OctoMap's OcTree).
  std::string backend = "grid";
  /// How a log-odds map integrates: "raycast", "culling", "superray" or "superray+culling".
  /// Every one gives the same map.
  std::string integration = "raycast";
  /// "set" (OctoMap's: a cell changes at most once per scan) or "per_ray".
  std::string update_rule = "set";
  /// The inverse sensor model (OctoMap's defaults).
  SensorProbabilities sensor{};
  /// Worker threads for integration and batched queries; 0: all cores.
  int threads = 0;
  /// Bounded memory (grid backend): after each scan, blocks farther than this from the
  /// sensor are dropped (0: off) ...
  double keep_radius_m = 0.0;
  /// ... and so are blocks outside this box (min, max corners, metres).
  std::optional<std::pair<Point3f, Point3f>> bounds{};
  /// Points a scan may hold (more are refused).
  std::size_t max_points = 2'000'000;
  /// false (default): inserts write the map in place; a query waits for an insert under way.
  /// true: every insert publishes a version, and queries read the latest one without waiting,
  /// also during an insert; the insert then copies each block it changes (copy on write),
  /// about a fifth more time a scan.
  bool versioned_reads = false;
  /// Keeps a distance field over the occupied cells (distance(), distanceBox()), updated with
  /// each insert from the cells whose class changed. Off by default.
  bool distance_field = false;
  /// The field's maximum distance (metres, 1 .. 28 cells): exact below it, reported as it
  /// beyond.
  double max_distance_m = 2.0;
  /// A map that forgets what moved: occupied cells not hit for `after_s` take a miss every
  /// `period_s` until they are unknown (docs/planner.md, "A map that forgets"). std::nullopt
  /// (default): off, and the map is OctoMap's exactly. Log-odds maps on the grid backend. The
  /// clock is each insert's `stamp_s` where given, else the time of the insert.
  std::optional<DecayOptions> decay;
};

/// What one cell holds.
struct CellInfo {
  CellState state = CellState::kUnknown;
  /// log(p / (1 - p)); none where unknown.
  std::optional<float> log_odds;
  /// p; 0.5 where unknown.
  [[nodiscard]] double probability() const;
};

/// What one scan did to the map.
struct InsertResult {
  /// The map version this scan published (one more than before).
  std::uint64_t version = 0;
  /// The 8^3 blocks the scan wrote (blockBox() turns a key into its box).
  std::vector<std::uint64_t> changed_blocks;
  std::size_t points = 0;
  /// Blocks and cells dropped after the scan by keep_radius_m / bounds.
  std::size_t evicted_blocks = 0;
  std::size_t evicted_cells = 0;
  /// Occupied cells that decayed before the scan (MapperOptions::decay): those that took a
  /// miss and stayed occupied, and those that became unknown.
  std::size_t decay_stepped_cells = 0;
  std::size_t decay_erased_cells = 0;
};

struct BoxCounts {
  std::size_t occupied = 0, free = 0, unknown = 0;
};

/// What a cast ray met.
struct RayHit {
  bool hit = false;
  /// The centre of the first occupied cell, and its distance from the origin.
  Point3f center = Point3f::Zero();
  float distance = 0.0F;
};

/// distance()'s answers (DistanceQueryResult), and the version they were read from.
struct Distances : DistanceQueryResult {
  std::uint64_t version = 0;
};

/// A dense box of the distance field: the distance (metres) of every cell from `min_center`
/// on, `size` cells an axis, x fastest, then y, then z.
struct DistanceGrid {
  Point3f min_center = Point3f::Zero();
  std::array<std::uint32_t, 3> size{};
  std::vector<float> distances;
};

/// Which cells forEachCell visits.
enum class CellFilter { kKnown, kOccupied, kFree };

/// An occupancy map in the caller's process: the server's engine (the same map kinds, the
/// same exactness: a log-odds Mapper equals OctoMap's insertPointCloud cell for cell) without
/// the server.
///
/// Thread-safety: every method may be called from any thread. The writers (insert*, clear,
/// clearBox) run one at a time: a second waits for the first. The const methods read the
/// latest version: by default they wait for a writer under way (and run side by side
/// otherwise); with MapperOptions::versioned_reads they never wait (a read during an insert
/// sees the version before it), but save() of a dense kind still waits for the writer (it
/// saves the kind's evidence with the cells).
class Mapper {
 public:
  /// A new, empty map; an error names the option that is out of range.
  [[nodiscard]] static Expected<Mapper> create(const MapperOptions& options = {});
  /// A map read from `path`: `.dmap` (densemap's snapshot: version, sensor model, and a dense
  /// map's evidence, so its kind goes on where it stopped) or `.bt` / `.ot` (OctoMap). The file
  /// decides the resolution (and, for `.dmap`, the sensor model and a dense kind); the other
  /// options are `options`'. Files are checked as the server's resume checks them: corrupt,
  /// truncated and non-finite contents are refused with the file and the reason.
  [[nodiscard]] static Expected<Mapper> load(const std::string& path,
                                             const MapperOptions& options = {});

  Mapper(Mapper&&) noexcept;
  Mapper& operator=(Mapper&&) noexcept;
  ~Mapper();

  /// Integrates one scan of world-frame points (metres) taken from `origin`, as OctoMap's
  /// OcTree::insertPointCloud(points, origin, max_range). Refused (the map unchanged) when
  /// empty, over max_points, or holding a NaN / Inf point. A writer.
  /// `stamp_s`: the scan's time in seconds, the decay clock (none: the time of the insert;
  /// refused unless finite and below 9 * 10^9 in magnitude).
  [[nodiscard]] Expected<InsertResult> insertPointCloud(std::span<const Point3f> points_world,
                                                        const Point3f& origin,
                                                        std::optional<double> stamp_s = {});
  /// The same without copying the points.
  [[nodiscard]] Expected<InsertResult> insertPointCloud(const PointCloud& points_world,
                                                        const Point3f& origin,
                                                        std::optional<double> stamp_s = {});
  /// The same for coordinates x y z per point (its length a multiple of 3).
  [[nodiscard]] Expected<InsertResult> insertPointCloud(std::span<const float> xyz_world,
                                                        const Point3f& origin,
                                                        std::optional<double> stamp_s = {});
  /// Integrates sensor-frame points with the sensor's pose in the world: each point is
  /// transformed in double and rounded to float once, the origin is the pose's translation.
  /// A writer.
  [[nodiscard]] Expected<InsertResult> insertScan(std::span<const Point3f> points_sensor,
                                                  const Eigen::Isometry3d& T_world_sensor,
                                                  std::optional<double> stamp_s = {});
  /// Forgets every cell (a new, empty version). A writer.
  void clear();
  /// Forgets the cells of the box [min, max] (metres): they become unknown; returns how many
  /// known cells it dropped. A writer.
  [[nodiscard]] Expected<std::size_t> clearBox(const Point3f& min, const Point3f& max);

  /// The cell holding `point` (metres; a non-finite or out-of-range point is unknown).
  [[nodiscard]] CellInfo query(const Point3f& point) const;
  /// The cells of many points, x y z each, into `log_odds` (NaN where unknown) and `states`
  /// (each as long as the points): batches run on the Mapper's threads, all from one version,
  /// which is returned.
  [[nodiscard]] Expected<std::uint64_t> query(std::span<const float> xyz, std::span<float> log_odds,
                                              std::span<CellState> states) const;
  /// Counts the cells of the box [min, max] (metres) by state; refused over `max_cells`.
  [[nodiscard]] Expected<BoxCounts> queryBox(const Point3f& min, const Point3f& max,
                                             std::size_t max_cells = 50'000'000) const;
  /// Walks the ray from `origin` along `direction` (any non-zero length) up to `max_range`
  /// metres (0 .. 10 km) with OctoMap's traversal; the first occupied cell is the hit, unknown
  /// cells are passed through.
  [[nodiscard]] Expected<RayHit> castRay(const Point3f& origin, const Point3f& direction,
                                         float max_range) const;
  /// Calls `f` with the centre (metres) and log-odds of every cell of the box [min, max] that
  /// `filter` selects, block by block, from one version.
  [[nodiscard]] Expected<void> forEachCell(
      const Point3f& min, const Point3f& max, CellFilter filter,
      const std::function<void(const Point3f& center, float log_odds)>& f) const;
  /// The same over the whole map.
  void forEachCell(CellFilter filter,
                   const std::function<void(const Point3f& center, float log_odds)>& f) const;

  /// Distances (metres) from the points `xyz` (x y z each) to the nearest occupied cell
  /// centre (or unknown cell, when options.unknown_as_occupied), with gradients and nearest
  /// obstacles, from one version. Needs MapperOptions::distance_field; refused for a NaN or
  /// out-of-range point or more than `max_points` points. Runs on the Mapper's threads.
  [[nodiscard]] Expected<Distances> distance(std::span<const float> xyz,
                                             const DistanceQueryOptions& options = {},
                                             std::size_t max_points = 10'000'000) const;
  /// The distance of every cell of the box [min, max] (metres); refused past `max_cells`.
  [[nodiscard]] Expected<DistanceGrid> distanceBox(const Point3f& min, const Point3f& max,
                                                   bool unknown_as_occupied = false,
                                                   std::size_t max_cells = 16'777'216) const;
  /// Whether a robot of radius `radius_m` can follow the polyline `xyz` (x y z per vertex):
  /// every cell within the radius of the path is considered (the capsules of its segments);
  /// the answer is occupied (with the first occupied cell along the path and its arc length),
  /// unknown or free. Needs no distance field.
  [[nodiscard]] Expected<SweptVolumeResult> checkPath(std::span<const float> xyz,
                                                      double radius_m) const;
  /// The same for a sequence of oriented boxes (a footprint along a trajectory).
  [[nodiscard]] Expected<SweptVolumeResult> checkBoxes(std::span<const OrientedBox> boxes) const;

  /// Writes the map to `path`: `.dmap` (densemap's snapshot, with a dense map's evidence),
  /// `.bt` (OctoMap binary: occupied and free) or `.ot` (OctoMap with log-odds); atomically.
  /// Returns the bytes written.
  [[nodiscard]] Expected<std::size_t> save(const std::string& path) const;

  /// The latest published version: 0 for a new map, one more per scan or change.
  [[nodiscard]] std::uint64_t version() const;
  [[nodiscard]] double resolution() const;
  [[nodiscard]] std::size_t knownCells() const;
  /// Bytes the map's storage holds.
  [[nodiscard]] std::size_t memoryBytes() const;
  /// The box (min, max corners, metres) of a block named in InsertResult::changed_blocks.
  [[nodiscard]] std::pair<Point3f, Point3f> blockBox(std::uint64_t block_key) const;
  [[nodiscard]] const MapperOptions& options() const;

 private:
  struct Impl;
  explicit Mapper(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace densemap
