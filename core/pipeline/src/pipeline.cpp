#include "densemap/pipeline/pipeline.hpp"

#include "densemap/geometry/percentile.hpp"

#include <tbb/flow_graph.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "densemap/geometry/stopwatch.hpp"

namespace densemap {

/// One scan's way through the graph; a rejected job passes through the later stages untouched.
struct Pipeline::Job {
  RawScan raw;
  std::optional<Rejection> rejection;
  Scan scan;
  PointCloud points_world;
  Point3f origin_world = Point3f::Zero();
  IntegrationResult result;
};

struct Pipeline::Graph {
  using JobPtr = std::shared_ptr<Job>;
  tbb::flow::graph graph;
  tbb::flow::function_node<JobPtr, JobPtr> validate;
  tbb::flow::function_node<JobPtr, JobPtr> transform;
  tbb::flow::function_node<JobPtr, JobPtr> integrate;
  tbb::flow::function_node<JobPtr> publish;

  explicit Graph(Pipeline& p)
      : validate(graph, tbb::flow::serial,
                 [&p](JobPtr job) {
                   auto scan = validateScan(job->raw, p.options_.limits);
                   if (scan) {
                     job->scan = std::move(*scan);
                   } else {
                     job->rejection = std::move(scan.error());
                   }
                   return job;
                 }),
        transform(graph, tbb::flow::serial,
                  [&p](JobPtr job) {
                    if (!job->rejection) {
                      if (p.options_.upsample) {
                        job->scan.points =
                            upsample::upsamplePoints(job->scan.points, *p.options_.upsample);
                        job->scan.intensities.clear();
                      }
                      job->points_world = job->scan.pointsWorld();
                      job->origin_world = job->scan.originWorld();
                    }
                    return job;
                  }),
        integrate(graph, tbb::flow::serial,
                  [&p](JobPtr job) {
                    if (!job->rejection) {
                      CellChanges* changes =
                          p.options_.collect_changes || p.mirror_ ? &job->result.changes : nullptr;
                      job->result.stats =
                          p.kernel_map_
                              ? p.integrateKernel(job->points_world, job->origin_world, changes)
                              : p.integrator_.integrate(*p.map_, job->points_world,
                                                        job->origin_world, changes);
                      p.evict(job->origin_world, job->result, changes);
                    }
                    return job;
                  }),
        publish(graph, tbb::flow::serial, [&p](const JobPtr& job) {
          if (job->rejection) {
            std::lock_guard lock(p.counters_mutex_);
            ++p.counters_.rejected;
            ++p.counters_.rejected_by_reason[static_cast<std::size_t>(job->rejection->reason)];
            p.sensors_.rejected(job->raw.sensor_id);
            p.counters_.last_reject_reason = job->rejection->message;
          } else {
            job->result.from_scan = true;
            job->result.sensor_id = job->raw.sensor_id;
            job->result.scan_seq = job->raw.seq;
            job->result.stamp_ns = job->raw.stamp_ns;
            job->result.latency_ms = std::chrono::duration<double, std::milli>(
                                         std::chrono::steady_clock::now() - job->raw.received)
                                         .count();
            p.publish(job->result);
          }
          if (job->rejection && p.on_reject_) p.on_reject_(job->raw, *job->rejection);
        }) {
    tbb::flow::make_edge(validate, transform);
    tbb::flow::make_edge(transform, integrate);
    tbb::flow::make_edge(integrate, publish);
  }
};

Expected<std::unique_ptr<Pipeline>> Pipeline::create(const PipelineOptions& options,
                                                     std::unique_ptr<OccupancyMap> initial,
                                                     std::uint64_t initial_version) {
  if (options.threads < 1 || options.threads > 256) return makeError("threads must be in 1..256");
  if (options.queue_depth < 1 || options.queue_depth > 1024) {
    return makeError("queue depth must be in 1..1024");
  }
  if (options.upsample) {
    if (auto ok = options.upsample->validate(); !ok) return std::unexpected(ok.error());
  }
  if ((options.keep_radius_m > 0 || options.bounds) && options.backend != Backend::kGrid) {
    return makeError("keep_radius_m and bounds (eviction) need the grid backend");
  }
  if (!initial) {
    auto map = makeMap(options.backend, options.resolution_m, SensorModel(options.sensor));
    if (!map) return std::unexpected(map.error());
    initial = std::move(*map);
  }
  return std::unique_ptr<Pipeline>(new Pipeline(options, std::move(initial), initial_version));
}

Pipeline::Pipeline(const PipelineOptions& options, std::unique_ptr<OccupancyMap> map,
                   std::uint64_t version)
    : options_(options),
      map_(std::move(map)),
      integrator_(
          {.method = options.method, .rule = options.rule, .max_range_m = options.max_range_m}),
      arena_(options.threads),
      queue_(
          options.queue_depth, options.queue_depth * kQueueSensorShare,
          [](const RawScan& scan) -> const std::string& { return scan.sensor_id; },
          SensorTally::kMaxSensors, rawScanBytes, options.queue_budget_bytes) {
  if (options.kernel) {
    auto kernel_options = kernel::KernelOptions::defaults(*options.kernel);
    kernel_options.max_range = options.max_range_m;
    kernel_map_ = std::make_unique<kernel::KernelMap>(options.resolution_m, kernel_options);
  }
  readable_ = dynamic_cast<GridMap*>(map_.get());
  if (readable_ == nullptr) {
    mirror_ = std::make_unique<GridMap>(map_->resolution(), map_->sensorModel());
    map_->forEachKnown([this](const VoxelKey& k, float v) { mirror_->setLogOdds(k, v); });
    readable_ = mirror_.get();
  }
  readable_->startVersionsAt(version);
  readable_->reserveBlocks(options.reserve_blocks);
  view_.store(MapView::publish(*readable_));
  // The graph belongs to the pipeline's arena: build it there.
  arena_.execute([this] { graph_ = std::make_unique<Graph>(*this); });
  if (options.warm_up && !kernel_map_) arena_.execute([this] { warmUp(); });
}

Pipeline::~Pipeline() { stop(); }

void Pipeline::start() {
  if (running_.exchange(true)) return;
  worker_ = std::thread([this] { run(); });
}

void Pipeline::stop() {
  if (!running_.exchange(false)) return;
  const auto discarded = queue_.close();
  {
    std::lock_guard lock(counters_mutex_);
    for (const RawScan& scan : discarded) sensors_.dropped(scan.sensor_id);
  }
  if (worker_.joinable()) worker_.join();
  runCommands();  // commands queued while stopping (e.g. the shutdown snapshot) still run
}

void Pipeline::submit(RawScan scan) {
  {
    std::lock_guard lock(counters_mutex_);
    ++counters_.received;
    sensors_.received(scan.sensor_id, scan.seq);
  }
  std::vector<RawScan> dropped;
  queue_.push(std::move(scan), &dropped);
  if (!dropped.empty()) {
    std::lock_guard lock(counters_mutex_);
    for (const RawScan& d : dropped) sensors_.dropped(d.sensor_id);
  }
}

std::future<Expected<std::string>> Pipeline::command(Command command) {
  std::promise<Expected<std::string>> promise;
  auto future = promise.get_future();
  {
    std::lock_guard lock(commands_mutex_);
    commands_.emplace_back(std::move(command), std::move(promise));
  }
  if (!running_.load()) runCommands();
  return future;
}

Pipeline::SavedState Pipeline::savedState() {
  SavedState state;
  // A command with no changes publishes nothing: the view it reads is the latest published,
  // the one the kernel map's evidence stands behind.
  auto done = command([&](OccupancyMap&, CellChanges&) -> Expected<std::string> {
    state.view = view_.load();
    if (kernel_map_) state.kernel = kernel_map_->evidence();
    return std::string();
  });
  done.wait();
  return state;
}

Expected<void> Pipeline::restoreKernelEvidence(const kernel::KernelEvidence& evidence) {
  if (running_.load()) return makeError("kernel evidence is restored before start()");
  if (!kernel_map_) {
    return makeError("the map kind is log_odds: kernel evidence of " +
                     std::string(kernel::kernelMethodName(evidence.method)) + " has no place");
  }
  return kernel_map_->restore(evidence);
}

void Pipeline::run() {
  while (running_.load()) {
    runCommands();
    auto raw = queue_.pop(std::chrono::milliseconds(20));
    if (raw) process(std::move(*raw));
  }
}

void Pipeline::process(RawScan raw) {
  auto job = std::make_shared<Job>();
  job->raw = std::move(raw);
  arena_.execute([&] {
    graph_->validate.try_put(job);
    graph_->graph.wait_for_all();
  });
}

void Pipeline::runCommands() {
  std::vector<std::pair<Command, std::promise<Expected<std::string>>>> pending;
  {
    std::lock_guard lock(commands_mutex_);
    pending.swap(commands_);
  }
  for (auto& [command, promise] : pending) {
    IntegrationResult result;
    Expected<std::string> outcome;
    arena_.execute([&] { outcome = command(*map_, result.changes); });
    if (kernel_map_) {  // erased cells lose their kernel evidence too
      for (const CellChange& c : result.changes) {
        if (!c.known) kernel_map_->erase(c.key);
      }
    }
    if (!result.changes.empty()) publish(result);
    promise.set_value(std::move(outcome));
  }
}

void Pipeline::publish(IntegrationResult& result) {
  if (mirror_) mirror_->applyChanges(result.changes);
  result.base_version = view_.load()->version();
  // The mirror follows the octree cell for cell, so its known-cell count is the map's.
  auto next =
      MapView::publish(*readable_, mirror_ ? map_->memoryBytes() : 0, &result.written_blocks);
  result.new_version = next->version();
  view_.store(next);
  if (result.from_scan) {
    std::lock_guard lock(counters_mutex_);
    ++counters_.integrated;
    counters_.evicted_blocks += result.evicted_blocks;
    counters_.evicted_cells += result.evicted_cells;
    sensors_.integrated(result.sensor_id);
    if (latencies_.size() < 1024) {
      latencies_.push_back(result.latency_ms);
    } else {
      latencies_[latency_next_] = result.latency_ms;
      latency_next_ = (latency_next_ + 1) % latencies_.size();
    }
  }
  if (publisher_) publisher_(result, next);
}

void Pipeline::evict(const Point3f& origin, IntegrationResult& result, CellChanges* changes) {
  // create() refuses eviction unless map_ is the GridMap itself (readable_, no mirror).
  if ((options_.keep_radius_m <= 0 && !options_.bounds) || mirror_) return;
  const double r2 = options_.keep_radius_m * options_.keep_radius_m;
  const auto keep = [&](const Point3f& centre) {
    if (options_.keep_radius_m > 0 && (centre - origin).cast<double>().squaredNorm() > r2) {
      return false;
    }
    if (const auto& box = options_.bounds) {
      return (centre.array() >= box->first.array()).all() &&
             (centre.array() <= box->second.array()).all();
    }
    return true;
  };
  const EvictStats stats = readable_->evictBlocks(keep, changes);
  // A kernel map drops the same blocks (its evidence and memory); its published map is the
  // grid above, whose changes say which cells became unknown.
  if (kernel_map_) kernel_map_->evictBlocks(keep);
  result.evicted_blocks = stats.blocks;
  result.evicted_cells = stats.cells;
}

void Pipeline::warmUp() {
  // A sparse fan (16 x 256 rays) at 90% of the max range (50 m when unlimited), +-3 deg about
  // the horizon: the rays' box (which sizes the dense free marks) is as wide as a real scan's,
  // and the blocks the rays touch size the per-worker update tables. Measured on the 64-beam
  // simulation at 0.1 m / 80 m: p99 about 220 -> 150 ms, for about 230 MB more RSS kept for
  // the life of the process (a 4 x 64 fan: +60 MB, no clear gain).
  const float range =
      0.9F * static_cast<float>(options_.max_range_m > 0 ? options_.max_range_m : 50.0);
  PointCloud points;
  points.reserve(16 * 256);
  for (int beam = 0; beam < 16; ++beam) {
    const float elevation = (-3.0F + 6.0F * static_cast<float>(beam) / 15.0F) * 0.0174533F;
    for (int col = 0; col < 256; ++col) {
      const float azimuth = 6.2831853F * static_cast<float>(col) / 256.0F;
      points.emplace_back(range * std::cos(elevation) * std::cos(azimuth),
                          range * std::cos(elevation) * std::sin(azimuth),
                          range * std::sin(elevation));
    }
  }
  GridMap scratch(options_.resolution_m, SensorModel(options_.sensor));
  // Twice: each TBB worker has its own buffers, and one pass may not reach every worker.
  for (int pass = 0; pass < 2; ++pass) {
    (void)integrator_.integrate(scratch, points, Point3f::Zero());
  }
}

ScanStats Pipeline::integrateKernel(const PointCloud& points_world, const Point3f& origin_world,
                                    CellChanges* changes) {
  auto t0 = std::chrono::steady_clock::now();
  std::vector<BlockCells> touched;
  kernel_map_->integrate(points_world, origin_world, &touched);
  ScanStats stats;
  stats.points = points_world.size();
  stats.rays = points_world.size();
  stats.ms_mark = msSince(t0);
  // The published map follows the evidence of the cells this scan reached: block by block, in
  // parallel, on the grid; cell by cell on another backend.
  const auto values = [this](std::uint64_t block_key, const block::BlockMask& cells,
                             std::array<float, block::kVoxels>& log_odds) {
    kernel_map_->blockLogOdds(block_key, cells, log_odds);
  };
  if (auto* grid = dynamic_cast<GridMap*>(map_.get())) {
    const ApplyStats applied = grid->assignBlocks(touched, values, changes);
    stats.updated = applied.updated_cells;
    stats.changed = applied.changed_cells;
  } else {
    std::array<float, block::kVoxels> log_odds{};
    for (const BlockCells& b : touched) {
      values(b.key, b.cells, log_odds);
      block::forEachSetBit(b.cells, [&](int cell) {
        const VoxelKey key = block::keyOf(b.key, cell);
        ++stats.updated;
        if (map_->logOdds(key) != log_odds[cell]) {
          map_->setLogOdds(key, log_odds[cell]);
          ++stats.changed;
          if (changes != nullptr) changes->push_back({key, log_odds[cell], true});
        }
      });
    }
  }
  stats.ms_apply = msSince(t0);
  return stats;
}

PipelineCounters Pipeline::counters() const {
  std::lock_guard lock(counters_mutex_);
  PipelineCounters c = counters_;
  c.dropped = queue_.dropped();
  c.sensors = sensors_.sensors();
  if (!latencies_.empty()) {
    std::vector<double> v = latencies_;
    std::sort(v.begin(), v.end());
    c.latency_p50_ms = nearestRank(v, 0.5);
    c.latency_p99_ms = nearestRank(v, 0.99);
  }
  return c;
}

}  // namespace densemap
