#pragma once

// densemap-bench's lanes: one (method, backend) each, its map and what it measured.
#include <tbb/task_arena.h>

#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "bench_report.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/planner/distance_field.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/raycast/integrator.hpp"

namespace densemap::bench {

struct WorldScan {
  PointCloud points;
  Point3f origin;
};

struct Options {
  std::string data;
  double resolution = 0.2;
  double max_range = -1.0;
  std::vector<std::string> methods{"octomap", "raycast", "superray+culling"};
  std::string rule = "set";
  std::size_t min_points = 20;
  std::vector<std::size_t> grow_strides = IntegratorOptions{}.grow_strides;
  std::vector<std::string> backends{"grid", "octree"};
  int threads = static_cast<int>(std::max(1U, std::thread::hardware_concurrency()));
  std::size_t first = 0;
  std::size_t limit = 0;
  std::size_t turn = 10;
  std::string json;
  std::vector<std::string> kernel_settings;  // --kernel-set, for every dense method
  std::size_t growth = 0;                    // --growth N: per-scan time as the map grows
  std::size_t cache_probe_mib = 4;           // --cache-probe-mib: 0, no probe
  double esdf_max_distance = 0.0;            // --esdf M: a distance field on grid lanes; 0 off
};

/// FNV-1a over a kernel map's evidence (keys, alpha, beta, in block order): equal digests mean
/// the same map bit for bit (a fast path against an earlier build, on the same scans).
[[nodiscard]] std::uint64_t evidenceDigest(const kernel::KernelEvidence& e);
/// A dense (kernel) method: `kind`, `kind@plain` (akimap_rays' plain path: a segment kernel
/// per piece of ray and an adaptive kernel per hit) or `kind@set=NAME=VALUE[:NAME=VALUE...]`
/// (these settings on this lane only), with --kernel-set applied first.
[[nodiscard]] Expected<kernel::KernelOptions> kernelOptions(const std::string& method,
                                                            const Options& o);

/// A method name and the worker threads of its lane: `METHOD@tN` is METHOD on N threads (1 ..
/// 256; a thread-scaling ratio in one run, the lanes taking turns), any other name `threads`.
/// An `@tN` that is not a number in range is left in the name (an unknown method then).
struct LaneMethod {
  std::string method;
  int threads = 1;
};
[[nodiscard]] LaneMethod laneMethod(const std::string& name, int threads);

using Integrate = std::function<ScanStats(OccupancyMap&, const WorldScan&)>;
/// The integrator of a log-odds method (octomap, raycast, superray, culling,
/// superray+culling) under o.rule; empty for anything else.
[[nodiscard]] Integrate makeIntegrator(const std::string& method, const Options& o);

/// One (method, backend) of a run: its map, its integrator and what it has measured so far.
/// Lanes take turns a few scans at a time (--turn), so that every method meets the machine in
/// the same state: a shared VM's speed drifts over seconds, and ratios of methods run one after
/// another drift with it. A few scans per turn keep each method's map warm in cache, as a
/// server's is between scans.
class Lane {
 public:
  Lane(const std::string& method, Backend backend, const Options& o)
      : Lane(method, laneMethod(method, method == "octomap" ? 1 : o.threads), backend, o) {}
  Lane(const std::string& method, const LaneMethod& base, Backend backend, const Options& o)
      : map_(std::move(*makeMap(backend, o.resolution))),
        integrate_(makeIntegrator(base.method, o)),
        arena_(base.threads) {
    map_->setRunner(tbbRunner());  // in the lane's arena
    r_.method = method;
    r_.backend = std::string(backendName(backend));
    r_.threads = base.threads;
    r_.rule = method == "octomap" ? "set" : o.rule;
    r_.resolution = o.resolution;
    r_.max_range = o.max_range;
    r_.has_counts = method != "octomap";
    if (auto k = kernelOptions(base.method, o); k) {
      r_.dense = true;
      r_.backend = "kernel";
      kernel_ = std::make_shared<kernel::KernelMap>(o.resolution, *k);
      integrate_ = [map = kernel_](OccupancyMap&, const WorldScan& s) {
        const kernel::KernelScanStats ks = map->integrate(s.points, s.origin);
        ScanStats stats;
        stats.points = s.points.size();
        stats.visits = ks.cell_updates + ks.free_visits;  // kernel cell updates + capsule voxels
        // No distinct-cell count: kernels and capsules overlap in ways the map does not record.
        // The dense stages in the stage columns (bench_report names them for dense lanes).
        stats.ms_rays = ks.ms_samples;
        stats.ms_region = ks.ms_kernels;
        stats.ms_mark = ks.ms_occupied;
        stats.ms_merge = ks.ms_free;
        stats.ms_apply = ks.ms_apply;
        return stats;
      };
    }
    name_ = method + "/" + r_.backend;
    auto* grid = dynamic_cast<GridMap*>(map_.get());
    if (o.esdf_max_distance > 0 && !kernel_ && grid != nullptr) {
      auto field = DistanceField::create(o.resolution, {.max_distance_m = o.esdf_max_distance});
      if (field) {
        field_ = std::move(*field);
        grid->startLiveVersions();
      } else {
        std::fprintf(stderr, "--esdf: %s\n", field.error().message.c_str());
      }
    }
  }

  /// Integrates one scan (the first of this lane's turn or not); returns its wall time, ms.
  double step(const WorldScan& scan, bool opens_turn) {
    ScanStats stats;
    const auto t0 = std::chrono::steady_clock::now();
    arena_.execute([&] { stats = integrate_(*map_, scan); });
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    r_.ms_per_scan.push_back(ms);
    (opens_turn ? r_.ms_opening_turn : r_.ms_within_turn).push_back(ms);
    r_.total_s += ms / 1000.0;
    r_.points += scan.points.size();
    const std::size_t counts[7] = {stats.visits,     stats.changed, stats.rays,
                                   stats.super_rays, stats.culled,  stats.region_voxels,
                                   stats.updated};
    for (int k = 0; k < 7; ++k) sums_[k] += static_cast<double>(counts[k]);
    const double stage[5] = {stats.ms_rays, stats.ms_region, stats.ms_mark, stats.ms_merge,
                             stats.ms_apply};
    for (int k = 0; k < 5; ++k) stage_sums_[k] += stage[k];
    region_ms_.push_back(stats.ms_region);
    if (field_) updateField();
    known_after_.push_back(kernel_ ? 0 : map_->knownCells());
    const auto* grid = dynamic_cast<const GridMap*>(map_.get());
    blocks_after_.push_back(grid != nullptr ? grid->store()->liveNodes() : 0);
    return ms;
  }

  /// --growth: the scans in `slices` consecutive parts, each part's p50 / p99 and the map's
  /// known cells and blocks after it (per-scan cost against map size).
  [[nodiscard]] std::string growthTable(std::size_t slices) const {
    std::string out;
    const std::size_t n = r_.ms_per_scan.size();
    if (n == 0 || slices == 0 || kernel_) return out;
    char line[160];
    for (std::size_t s = 0; s < slices; ++s) {
      const std::size_t from = n * s / slices, to = n * (s + 1) / slices;
      if (to <= from) continue;
      const std::vector<double> part(r_.ms_per_scan.begin() + static_cast<std::ptrdiff_t>(from),
                                     r_.ms_per_scan.begin() + static_cast<std::ptrdiff_t>(to));
      double region = 0.0;
      for (std::size_t i = from; i < to; ++i) region += region_ms_[i];
      std::snprintf(line, sizeof(line), "%-28s %5zu-%-5zu %9.1f %9.1f %10.2f %12zu %9zu\n",
                    name_.c_str(), from + 1, to, densemap::percentile(part, 0.5),
                    densemap::percentile(part, 0.99), region / static_cast<double>(to - from),
                    known_after_[to - 1], blocks_after_[to - 1]);
      out += line;
    }
    return out;
  }

  /// The result after the last scan (per-scan means of the counts and stage times).
  RunResult finish() {
    r_.scans = r_.ms_per_scan.size();
    const double n = static_cast<double>(std::max<std::size_t>(1, r_.scans));
    r_.visits_per_scan = sums_[0] / n;
    r_.changed_cells_per_scan = sums_[1] / n;
    r_.rays_per_scan = sums_[2] / n;
    r_.super_rays_per_scan = sums_[3] / n;
    r_.culled_per_scan = sums_[4] / n;
    r_.region_voxels_per_scan = sums_[5] / n;
    r_.cells_per_scan = sums_[6] / n;
    for (int k = 0; k < 5; ++k) r_.ms_stage[k] = stage_sums_[k] / n;
    r_.known_cells = kernel_ ? kernel_->knownCells() : map_->knownCells();
    r_.memory_bytes = kernel_ ? kernel_->memoryBytes() : map_->memoryBytes();
    if (field_) r_.field_bytes = field_->memoryBytes();
    if (kernel_) r_.evidence_digest = evidenceDigest(kernel_->evidence());
    return r_;
  }

  [[nodiscard]] const std::string& name() const { return name_; }
  /// The distance field (--esdf), if the lane keeps one.
  [[nodiscard]] const DistanceField* field() const { return field_ ? &*field_ : nullptr; }
  /// A view of the lane's map as the field last saw it (--esdf lanes only).
  [[nodiscard]] std::shared_ptr<const MapView> fieldView() {
    return MapView::advanceLive(dynamic_cast<GridMap&>(*map_));
  }
  [[nodiscard]] int threads() const { return r_.threads; }
  [[nodiscard]] const OccupancyMap& map() const { return *map_; }

 private:
  /// --esdf: ends the scan's version and brings the field up to date from the blocks it
  /// wrote, timed as its own stage (not in the scan's time).
  void updateField() {
    std::vector<std::uint64_t> written;
    const auto t0 = std::chrono::steady_clock::now();
    arena_.execute([&] {
      const auto view = MapView::advanceLive(dynamic_cast<GridMap&>(*map_), 0, &written);
      const DistanceUpdateStats s = field_->update(*view, written, tbbRunner());
      field_changes_ += static_cast<double>(s.added + s.removed);
    });
    r_.esdf_ms.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    r_.esdf_changes_per_scan = field_changes_ / static_cast<double>(r_.esdf_ms.size());
  }

  RunResult r_;
  std::unique_ptr<OccupancyMap> map_;
  std::optional<DistanceField> field_;
  double field_changes_ = 0;
  Integrate integrate_;
  std::shared_ptr<kernel::KernelMap> kernel_;  // dense methods: the map they build
  tbb::task_arena arena_;
  double sums_[7] = {0, 0, 0, 0, 0, 0, 0};
  double stage_sums_[5] = {0, 0, 0, 0, 0};
  std::vector<std::size_t> known_after_, blocks_after_;  // the map after each scan
  std::vector<double> region_ms_;                        // each scan's culling-region stage
  std::string name_;
};

}  // namespace densemap::bench
