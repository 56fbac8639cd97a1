#include "densemap/pipeline/engine.hpp"

#include "map_kind.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/parallel/tbb_runner.hpp"

namespace densemap {
namespace {

constexpr double kMaxRayCells = 65536.0;

/// A number as a person would write it: 1e-09, not 0.000000.
std::string numberText(double v) {
  char text[32];
  std::snprintf(text, sizeof(text), "%g", v);
  return text;
}

/// The steady clock's time, ns (the decay clock when scans are not stamped).
std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

Expected<void> checkMapOptions(const PipelineOptions& o) {
  if (!(o.resolution_m >= 0.001 && o.resolution_m <= 100.0)) {
    return makeError("resolution_m must be in [0.001, 100], got " + numberText(o.resolution_m));
  }
  if (std::isnan(o.max_range_m) ||
      (o.max_range_m >= 0 && !(o.max_range_m > 0 && o.max_range_m <= kMaxRangeM))) {
    return makeError("max_range_m must be < 0 (unlimited) or in (0, " +
                     std::to_string(int(kMaxRangeM)) + "] m, got " + numberText(o.max_range_m));
  }
  if (o.max_range_m > 0 && o.max_range_m / o.resolution_m > kMaxRayCells) {
    return makeError("max_range_m / resolution_m must be at most " +
                     std::to_string(int(kMaxRayCells)) + " cells per ray, got " +
                     numberText(o.max_range_m / o.resolution_m));
  }
  if (!std::isfinite(o.keep_radius_m) || o.keep_radius_m < 0) {
    return makeError("keep_radius_m must be >= 0");
  }
  if (const auto& b = o.bounds) {
    if (!b->first.allFinite() || !b->second.allFinite() ||
        (b->first.array() >= b->second.array()).any()) {
      return makeError("bounds needs finite min_x < max_x, min_y < max_y, min_z < max_z");
    }
  }
  if ((o.keep_radius_m > 0 || o.bounds) && o.backend != Backend::kGrid) {
    return makeError("keep_radius_m and bounds (eviction) need backend \"grid\"");
  }
  if (o.decay) {
    if (auto ok = checkDecayOptions(*o.decay); !ok) {
      return makeError("decay: " + ok.error().message);
    }
    if (o.kernel || o.backend != Backend::kGrid) {
      return makeError("decay needs the log_odds map kind on backend \"grid\"");
    }
  }
  const auto& s = o.sensor;
  if (!SensorModel(s).isValid() || s.hit >= 1.0 || s.clamp_max >= 1.0 || s.miss <= 0.0 ||
      s.clamp_min <= 0.0) {
    return makeError(
        "sensor needs 0 < clamp_min < 0.5, prob_miss < 0.5 < prob_hit < 1, "
        "0.5 < clamp_max < 1");
  }
  return {};
}

Expected<std::unique_ptr<Engine>> Engine::create(const PipelineOptions& options,
                                                 std::unique_ptr<OccupancyMap> initial,
                                                 std::uint64_t initial_version) {
  if (options.upsample) {
    if (auto ok = options.upsample->validate(); !ok) return std::unexpected(ok.error());
  }
  if (auto ok = checkMapOptions(options); !ok) return std::unexpected(ok.error());
  if (!initial) {
    auto map = makeMap(options.backend, options.resolution_m, SensorModel(options.sensor));
    if (!map) return std::unexpected(map.error());
    initial = std::move(*map);
  }
  return std::unique_ptr<Engine>(new Engine(options, std::move(initial), initial_version));
}

Engine::Engine(const PipelineOptions& options, std::unique_ptr<OccupancyMap> map,
               std::uint64_t version)
    : options_(options) {
  map->setRunner(tbbRunner());  // a restored map too: its blocks in parallel, in the arena
  if (options.kernel) {
    auto kernel_options = kernel::KernelOptions::defaults(*options.kernel);
    kernel_options.max_range = options.max_range_m;
    kind_ = makeKernelKind(std::move(map), kernel_options);
  } else {
    kind_ = makeLogOddsKind(
        std::move(map),
        {.method = options.method, .rule = options.rule, .max_range_m = options.max_range_m});
  }
  if (options.decay) decay_ = std::make_unique<OccupancyDecay>(*options.decay);
  kind_->published().startVersionsAt(version);
  kind_->published().reserveBlocks(options.reserve_blocks);
  if (options.versioned_views) {
    view_.store(MapView::publish(kind_->published()));
  } else {
    kind_->published().startLiveVersions();
    view_.store(MapView::advanceLive(kind_->published()));
  }
}

Engine::~Engine() = default;

std::expected<IntegrationResult, Rejection> Engine::integrate(const RawScan& raw) {
  auto scan = validateScan(raw, options_.limits);
  if (!scan) return std::unexpected(std::move(scan.error()));
  PointCloud points_world;
  Point3f origin_world = Point3f::Zero();
  transform(*scan, points_world, origin_world);
  const bool stamped = decay_ && decay_->options().use_stamps;
  IntegrationResult result =
      integratePoints(points_world, origin_world, stamped ? raw.stamp_ns : steadyNowNs());
  result.sensor_id = raw.sensor_id;
  result.scan_seq = raw.seq;
  result.stamp_ns = raw.stamp_ns;
  result.T_world_sensor = scan->T_world_sensor;
  result.points_world = std::make_shared<const PointCloud>(std::move(points_world));
  return result;
}

std::expected<IntegrationResult, Rejection> Engine::integrateWorld(
    const PointCloud& points_world, const Point3f& origin_world,
    std::optional<std::int64_t> stamp_ns) {
  if (auto ok = checkWorldScan(points_world, origin_world, options_.limits); !ok) {
    return std::unexpected(std::move(ok.error()));
  }
  return integratePoints(points_world, origin_world, stamp_ns.value_or(steadyNowNs()));
}

IntegrationResult Engine::integratePoints(const PointCloud& points_world,
                                          const Point3f& origin_world, std::int64_t now_ns) {
  IntegrationResult result;
  CellChanges* changes =
      options_.collect_changes || kind_->needsChanges() ? &result.changes : nullptr;
  decayBefore(now_ns, result, changes);
  result.stats =
      kind_->integrate(raysReachingBounds(points_world, origin_world), origin_world, changes);
  observeHits(now_ns);
  evict(origin_world, result, changes);
  result.from_scan = true;
  publish(result);
  return result;
}

void Engine::transform(Scan& scan, PointCloud& points_world, Point3f& origin_world) const {
  if (options_.upsample) {
    scan.points = upsample::upsamplePoints(scan.points, *options_.upsample);
    scan.intensities.clear();
  }
  points_world = scan.pointsWorld();
  origin_world = scan.originWorld();
}

Expected<std::string> Engine::command(const Command& command, IntegrationResult& result) {
  Expected<std::string> outcome = kind_->command(command, result.changes);
  if (!result.changes.empty()) publish(result);
  return outcome;
}

void Engine::warmUp() { kind_->warmUp(options_.max_range_m); }

std::optional<kernel::KernelEvidence> Engine::evidence() const { return kind_->evidence(); }

Expected<void> Engine::restore(const kernel::KernelEvidence& evidence) {
  return kind_->restore(evidence);
}

void Engine::publish(IntegrationResult& result) {
  kind_->beforePublish(result.changes);
  result.base_version = view_.load()->version();
  // A mirror follows the octree cell for cell, so its known-cell count is the map's.
  auto next =
      options_.versioned_views
          ? MapView::publish(kind_->published(), kind_->ownBytes(), &result.written_blocks)
          : MapView::advanceLive(kind_->published(), kind_->ownBytes(), &result.written_blocks);
  result.new_version = next->version();
  view_.store(std::move(next));
}

void Engine::decayBefore(std::int64_t now_ns, IntegrationResult& result, CellChanges* changes) {
  if (!decay_) return;
  // checkMapOptions allows decay on the grid backend only: the map is the published grid.
  result.decayed = decay_->decay(kind_->published(), now_ns, changes);
}

void Engine::observeHits(std::int64_t now_ns) {
  if (!decay_) return;
  // The cells the scan hit: the occupied end cells of the rays the integrator just marked
  // (checkMapOptions allows decay on the log-odds kind only), in the scan's order.
  hits_.clear();
  for (const RayEnd& ray : kind_->rayEnds()) {
    if (ray.occupied && ray.key_valid) hits_.push_back(ray.key);
  }
  decay_->observe(hits_, now_ns);
}

void Engine::evict(const Point3f& origin, IntegrationResult& result, CellChanges* changes) {
  // create() refuses eviction unless the map is the grid itself (no mirror).
  if ((options_.keep_radius_m <= 0 && !options_.bounds) || !kind_->canEvict()) return;
  const double r2 = options_.keep_radius_m * options_.keep_radius_m;
  const auto keep = [&](const Point3f& centre) {
    if (options_.keep_radius_m > 0 && (centre - origin).cast<double>().squaredNorm() > r2) {
      return false;
    }
    if (const auto& box = options_.bounds) return block::boxKeeps(box->first, box->second, centre);
    return true;
  };
  const EvictStats stats = kind_->evict(keep, changes);
  result.evicted_blocks = stats.blocks;
  result.evicted_cells = stats.cells;
}

bool segmentMeetsBox(const Point3f& from, const Point3f& to, const Point3f& lo, const Point3f& hi) {
  double t0 = 0.0, t1 = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double o = from[a], d = static_cast<double>(to[a]) - o;
    if (d == 0.0) {
      if (o < lo[a] || o > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o) / d, tb = (hi[a] - o) / d;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

const PointCloud& Engine::raysReachingBounds(const PointCloud& points_world,
                                             const Point3f& origin) {
  if (!options_.bounds || options_.kernel) return points_world;
  // Every cell of a kept block lies within the box grown by its keep margin.
  const auto margin = static_cast<float>(block::boxKeepMargin(options_.resolution_m));
  const Point3f lo = options_.bounds->first - Point3f::Constant(margin);
  const Point3f hi = options_.bounds->second + Point3f::Constant(margin);
  const double max_range = options_.max_range_m;
  rays_in_bounds_.clear();
  for (const Point3f& p : points_world) {
    // A ray ending in the box meets it; only the others need the slab test.
    if ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all()) {
      rays_in_bounds_.push_back(p);
      continue;
    }
    Point3f end = p;
    const double length2 = (p - origin).cast<double>().squaredNorm();
    if (max_range >= 0 && length2 > max_range * max_range) {
      end = origin + ((p - origin).cast<double>() * (max_range / std::sqrt(length2))).cast<float>();
    }
    if (segmentMeetsBox(origin, end, lo, hi)) rays_in_bounds_.push_back(p);
  }
  return rays_in_bounds_;
}

}  // namespace densemap
