#include "densemap/mapper/mapper.hpp"

#include <tbb/task_arena.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <mutex>
#include <shared_mutex>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/pipeline/engine.hpp"
#include "densemap/planner/distance_field.hpp"
#include "densemap/planner/distance_query.hpp"
#include "densemap/planner/swept_volume.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/store/snapshot.hpp"

namespace densemap {

struct Mapper::Impl {
  MapperOptions options;
  PipelineOptions pipeline;
  std::unique_ptr<tbb::task_arena> arena;
  std::unique_ptr<Engine> engine;
  /// Writers hold it alone. Readers share it, unless versioned_reads (then only save() of a
  /// dense kind takes it, shared: the evidence belongs to the writer).
  mutable std::shared_mutex lock;
  /// The distance field (MapperOptions::distance_field), updated by the writer under `lock`;
  /// its readers always take the lock, shared.
  std::optional<DistanceField> field;

  /// What a reader holds while it reads.
  [[nodiscard]] std::shared_lock<std::shared_mutex> reading() const {
    return options.versioned_reads ? std::shared_lock<std::shared_mutex>()
                                   : std::shared_lock<std::shared_mutex>(lock);
  }

  [[nodiscard]] std::shared_ptr<const MapView> view() const { return engine->view(); }
  [[nodiscard]] Expected<InsertResult> insert(const PointCloud& points_world,
                                              const Point3f& origin,
                                              std::optional<double> stamp_s);
  /// Brings the field up to date with the blocks a version wrote (writer, under the lock).
  void updateField(std::span<const std::uint64_t> blocks) {
    if (field) arena->execute([&] { field->update(*view(), blocks, tbbRunner()); });
  }
  /// Erases the cells of the key box [lo, hi]; returns how many were known.
  std::size_t erase(const VoxelKey& lo, const VoxelKey& hi);
  /// A Mapper's engine over `initial` (none: an empty map), in its arena.
  [[nodiscard]] static Expected<std::unique_ptr<Impl>> make(const MapperOptions& options,
                                                            std::unique_ptr<OccupancyMap> initial,
                                                            std::uint64_t version);
};

namespace {

/// The engine's options for `o`, or the option that is wrong.
Expected<PipelineOptions> pipelineOptionsOf(const MapperOptions& o) {
  PipelineOptions p;
  auto backend = parseBackend(o.backend);
  if (!backend) return makeError("backend: " + backend.error().message);
  p.backend = *backend;
  auto kind = kernel::parseMapKind(o.kind);
  if (!kind) return makeError("kind: " + kind.error().message);
  p.kernel = *kind;
  auto method = parseIntegrationMethod(o.integration);
  if (!method) return makeError("integration: " + method.error().message);
  p.method = *method;
  auto rule = parseUpdateRule(o.update_rule);
  if (!rule) return makeError("update_rule: " + rule.error().message);
  p.rule = *rule;
  p.resolution_m = o.resolution_m;
  p.max_range_m = o.max_range_m;
  p.sensor = o.sensor;
  p.keep_radius_m = o.keep_radius_m;
  p.bounds = o.bounds;
  if (o.threads < 0 || o.threads > 256)
    return makeError("threads must be in 0 .. 256 (0: all cores)");
  if (o.max_points == 0) return makeError("max_points must be > 0");
  p.limits.max_points = o.max_points;
  // The map's addressable range bounds where a sensor may be.
  p.limits.max_abs_position_m = kMaxPoseTranslationM;
  // A library map grows as it is used: no pool faulted in up front.
  p.reserve_blocks = 0;
  p.versioned_views = o.versioned_reads;
  p.decay = o.decay;
  if (auto ok = checkMapOptions(p); !ok) return std::unexpected(ok.error());
  return p;
}

}  // namespace

Expected<std::unique_ptr<Mapper::Impl>> Mapper::Impl::make(const MapperOptions& options,
                                                           std::unique_ptr<OccupancyMap> initial,
                                                           std::uint64_t version) {
  auto pipeline = pipelineOptionsOf(options);
  if (!pipeline) return std::unexpected(pipeline.error());
  auto impl = std::make_unique<Mapper::Impl>();
  impl->options = options;
  impl->pipeline = *pipeline;
  const int automatic = tbb::task_arena::automatic;
  impl->arena =
      std::make_unique<tbb::task_arena>(options.threads > 0 ? options.threads : automatic);
  Expected<std::unique_ptr<Engine>> engine = makeError("");
  impl->arena->execute(
      [&] { engine = Engine::create(impl->pipeline, std::move(initial), version); });
  if (!engine) return std::unexpected(engine.error());
  impl->engine = std::move(*engine);
  if (options.distance_field) {
    auto field = DistanceField::create(impl->pipeline.resolution_m,
                                       {.max_distance_m = options.max_distance_m});
    if (!field) return makeError("max_distance_m: " + field.error().message);
    impl->field = std::move(*field);
    impl->arena->execute([&] { impl->field->rebuild(*impl->view(), tbbRunner()); });
  }
  return impl;
}

double CellInfo::probability() const {
  return log_odds ? SensorModel::probability(*log_odds) : 0.5;
}

Mapper::Mapper(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Mapper::Mapper(Mapper&&) noexcept = default;
Mapper& Mapper::operator=(Mapper&&) noexcept = default;
Mapper::~Mapper() = default;

Expected<Mapper> Mapper::create(const MapperOptions& options) {
  auto impl = Impl::make(options, nullptr, 0);
  if (!impl) return std::unexpected(impl.error());
  return Mapper(std::move(*impl));
}

Expected<Mapper> Mapper::load(const std::string& path, const MapperOptions& options) {
  const std::filesystem::path file(path);
  auto backend = parseBackend(options.backend);
  if (!backend) return makeError("backend: " + backend.error().message);
  MapperOptions o = options;
  const std::string ext = file.extension().string();
  if (ext == ".bt" || ext == ".ot") {
    auto map = importOctomap(file, *backend);
    if (!map) return std::unexpected(map.error());
    o.resolution_m = (*map)->resolution();
    o.sensor = (*map)->sensorModel().probabilities();
    auto impl = Impl::make(o, std::move(*map), 0);
    if (!impl) return std::unexpected(impl.error());
    return Mapper(std::move(*impl));
  }
  auto loaded = loadSnapshot(file, *backend, 0.0);
  if (!loaded) return std::unexpected(loaded.error());
  o.resolution_m = loaded->map->resolution();
  o.sensor = loaded->map->sensorModel().probabilities();
  if (loaded->kernel) o.kind = std::string(kernel::kernelMethodName(loaded->kernel->method));
  auto impl = Impl::make(o, std::move(loaded->map), loaded->version);
  if (!impl) return std::unexpected(impl.error());
  if (loaded->kernel) {
    if (auto ok = (*impl)->engine->restore(*loaded->kernel); !ok) {
      return makeError(path + ": " + ok.error().message);
    }
  }
  return Mapper(std::move(*impl));
}

Expected<InsertResult> Mapper::Impl::insert(const PointCloud& points_world, const Point3f& origin,
                                            std::optional<double> stamp_s) {
  std::optional<std::int64_t> stamp_ns;
  if (stamp_s) {
    if (!(std::abs(*stamp_s) < 9e9)) return makeError("stamp must be finite and below 9e9 s");
    stamp_ns = std::llround(*stamp_s * 1e9);
  }
  std::expected<IntegrationResult, Rejection> r = std::unexpected(Rejection{});
  const std::unique_lock writing(lock);
  arena->execute([&] { r = engine->integrateWorld(points_world, origin, stamp_ns); });
  if (!r) return makeError(r.error().message);
  updateField(r->written_blocks);
  InsertResult out;
  out.version = r->new_version;
  out.changed_blocks = std::move(r->written_blocks);
  out.points = points_world.size();
  out.evicted_blocks = r->evicted_blocks;
  out.evicted_cells = r->evicted_cells;
  out.decay_stepped_cells = r->decayed.stepped;
  out.decay_erased_cells = r->decayed.erased;
  return out;
}

Expected<InsertResult> Mapper::insertPointCloud(std::span<const Point3f> points_world,
                                                const Point3f& origin,
                                                std::optional<double> stamp_s) {
  return impl_->insert(PointCloud(points_world.begin(), points_world.end()), origin, stamp_s);
}

Expected<InsertResult> Mapper::insertPointCloud(const PointCloud& points_world,
                                                const Point3f& origin,
                                                std::optional<double> stamp_s) {
  return impl_->insert(points_world, origin, stamp_s);
}

Expected<InsertResult> Mapper::insertPointCloud(std::span<const float> xyz_world,
                                                const Point3f& origin,
                                                std::optional<double> stamp_s) {
  if (auto ok = checkPointCoordinates(xyz_world.size()); !ok) return std::unexpected(ok.error());
  PointCloud points(xyz_world.size() / 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    points[i] = Point3f(xyz_world[3 * i], xyz_world[3 * i + 1], xyz_world[3 * i + 2]);
  }
  return impl_->insert(points, origin, stamp_s);
}

Expected<InsertResult> Mapper::insertScan(std::span<const Point3f> points_sensor,
                                          const Eigen::Isometry3d& T_world_sensor,
                                          std::optional<double> stamp_s) {
  if (auto ok = checkRigidPose(T_world_sensor); !ok) return std::unexpected(ok.error());
  const PointCloud sensor(points_sensor.begin(), points_sensor.end());
  return impl_->insert(transformPoints(T_world_sensor, sensor), sensorOrigin(T_world_sensor),
                       stamp_s);
}

std::size_t Mapper::Impl::erase(const VoxelKey& lo, const VoxelKey& hi) {
  std::size_t erased = 0;
  IntegrationResult result;
  const std::unique_lock writing(lock);
  arena->execute([&] {
    (void)engine->command(
        [&](OccupancyMap& map, CellChanges& changes) -> Expected<std::string> {
          erased = map.clearBox(lo, hi, &changes);
          return std::string();
        },
        result);
  });
  updateField(result.written_blocks);
  return erased;
}

void Mapper::clear() { impl_->erase(VoxelKey{0, 0, 0}, VoxelKey{65535, 65535, 65535}); }

Expected<std::size_t> Mapper::clearBox(const Point3f& min, const Point3f& max) {
  const auto keys = boxKeys(impl_->view()->grid(), min, max);
  if (!keys) return std::unexpected(keys.error());
  return impl_->erase(keys->first, keys->second);
}

CellInfo Mapper::query(const Point3f& point) const {
  const auto reading = impl_->reading();
  const auto view = impl_->view();
  CellInfo info;
  const auto key = point.allFinite() ? view->grid().pointToKey(point) : std::nullopt;
  if (key) info.log_odds = view->logOdds(*key);
  info.state = cellState(info.log_odds);
  return info;
}

Expected<std::uint64_t> Mapper::query(std::span<const float> xyz, std::span<float> log_odds,
                                      std::span<CellState> states) const {
  if (auto ok = checkPointCoordinates(xyz.size()); !ok) return std::unexpected(ok.error());
  const std::size_t n = xyz.size() / 3;
  if (log_odds.size() != n || states.size() != n) {
    return makeError("query: " + std::to_string(n) + " points but " +
                     std::to_string(log_odds.size()) + " log-odds and " +
                     std::to_string(states.size()) + " states to fill");
  }
  const auto reading = impl_->reading();
  const auto view = impl_->view();
  Expected<PointQueryResult> r = makeError("");
  impl_->arena->execute(
      [&] { r = queryPoints(*view, xyz, std::numeric_limits<std::size_t>::max(), tbbRunner()); });
  if (!r) return std::unexpected(r.error());
  std::copy(r->log_odds.begin(), r->log_odds.end(), log_odds.begin());
  for (std::size_t i = 0; i < n; ++i) states[i] = static_cast<CellState>(r->states[i]);
  return view->version();
}

Expected<BoxCounts> Mapper::queryBox(const Point3f& min, const Point3f& max,
                                     std::size_t max_cells) const {
  const auto reading = impl_->reading();
  auto r = densemap::queryBox(*impl_->view(), min, max, max_cells, 0);
  if (!r) return std::unexpected(r.error());
  return BoxCounts{r->occupied, r->free, r->unknown};
}

Expected<RayHit> Mapper::castRay(const Point3f& origin, const Point3f& direction,
                                 float max_range) const {
  const auto reading = impl_->reading();
  auto r = densemap::castRay(*impl_->view(), origin, direction, max_range);
  if (!r) return std::unexpected(r.error());
  return RayHit{r->hit, r->hit_center, r->distance};
}

namespace {

bool selected(CellFilter filter, float log_odds) {
  switch (filter) {
    case CellFilter::kKnown:
      return true;
    case CellFilter::kOccupied:
      return SensorModel::isOccupied(log_odds);
    case CellFilter::kFree:
      return !SensorModel::isOccupied(log_odds);
  }
  return false;
}

}  // namespace

Expected<void> Mapper::forEachCell(
    const Point3f& min, const Point3f& max, CellFilter filter,
    const std::function<void(const Point3f& center, float log_odds)>& f) const {
  const auto reading = impl_->reading();
  const auto view = impl_->view();
  return forEachKnownInBox(*view, min, max, [&](const VoxelKey& k, float v) {
    if (selected(filter, v)) f(view->grid().keyToPoint(k), v);
  });
}

void Mapper::forEachCell(
    CellFilter filter, const std::function<void(const Point3f& center, float log_odds)>& f) const {
  const auto reading = impl_->reading();
  const auto view = impl_->view();
  view->forEachKnown([&](const VoxelKey& k, float v) {
    if (selected(filter, v)) f(view->grid().keyToPoint(k), v);
  });
}

Expected<Distances> Mapper::distance(std::span<const float> xyz,
                                     const DistanceQueryOptions& options,
                                     std::size_t max_points) const {
  if (!impl_->field)
    return makeError("distance: the Mapper has no distance field (distance_field)");
  const std::shared_lock reading(impl_->lock);
  const auto view = impl_->view();
  Expected<DistanceQueryResult> r = makeError("");
  impl_->arena->execute(
      [&] { r = queryDistances(*impl_->field, *view, xyz, options, max_points, tbbRunner()); });
  if (!r) return std::unexpected(r.error());
  Distances out;
  static_cast<DistanceQueryResult&>(out) = std::move(*r);
  out.version = view->version();
  return out;
}

Expected<DistanceGrid> Mapper::distanceBox(const Point3f& min, const Point3f& max,
                                           bool unknown_as_occupied, std::size_t max_cells) const {
  if (!impl_->field)
    return makeError("distance: the Mapper has no distance field (distance_field)");
  const std::shared_lock reading(impl_->lock);
  const auto view = impl_->view();
  auto box = exportDistanceBox(*impl_->field, *view, min, max, unknown_as_occupied, max_cells);
  if (!box) return std::unexpected(box.error());
  return DistanceGrid{view->grid().keyToPoint(box->min), box->size, std::move(box->distances)};
}

Expected<SweptVolumeResult> Mapper::checkPath(std::span<const float> xyz, double radius_m) const {
  const auto reading = impl_->reading();
  return densemap::checkPath(*impl_->view(), xyz, radius_m);
}

Expected<SweptVolumeResult> Mapper::checkBoxes(std::span<const OrientedBox> boxes) const {
  const auto reading = impl_->reading();
  return densemap::checkBoxes(*impl_->view(), boxes);
}

Expected<std::size_t> Mapper::save(const std::string& path) const {
  // A dense kind's evidence belongs to the writer: read it between scans, with the view of
  // the same version (versioned reads need no lock for the cells alone).
  const auto reading = impl_->options.versioned_reads && !impl_->pipeline.kernel
                           ? std::shared_lock<std::shared_mutex>()
                           : std::shared_lock<std::shared_mutex>(impl_->lock);
  const auto view = impl_->view();
  const auto evidence = impl_->engine->evidence();
  return saveSnapshot(*view, SensorModel(impl_->pipeline.sensor), impl_->pipeline.backend, path,
                      evidence ? &*evidence : nullptr);
}

std::uint64_t Mapper::version() const { return impl_->view()->version(); }

double Mapper::resolution() const { return impl_->pipeline.resolution_m; }

std::size_t Mapper::knownCells() const { return impl_->view()->knownCells(); }

std::size_t Mapper::memoryBytes() const { return impl_->view()->memoryBytes(); }

std::pair<Point3f, Point3f> Mapper::blockBox(std::uint64_t block_key) const {
  const VoxelGrid& grid = impl_->view()->grid();
  const Point3f half = Point3f::Constant(static_cast<float>(grid.resolution() / 2));
  return {grid.keyToPoint(block::keyOf(block_key, 0)) - half,
          grid.keyToPoint(block::keyOf(block_key, block::kVoxels - 1)) + half};
}

const MapperOptions& Mapper::options() const { return impl_->options; }

}  // namespace densemap
