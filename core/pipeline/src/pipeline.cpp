#include "densemap/pipeline/pipeline.hpp"

#include "densemap/geometry/percentile.hpp"

#include <tbb/flow_graph.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "map_kind.hpp"

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
                      CellChanges* changes = p.options_.collect_changes || p.kind_->needsChanges()
                                                 ? &job->result.changes
                                                 : nullptr;
                      job->result.stats =
                          p.kind_->integrate(job->points_world, job->origin_world, changes);
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
      arena_(options.threads),
      queue_(
          options.queue_depth, options.queue_depth * kQueueSensorShare,
          [](const RawScan& scan) -> const std::string& { return scan.sensor_id; },
          SensorTally::kMaxSensors, rawScanBytes, options.queue_budget_bytes) {
  if (options.kernel) {
    auto kernel_options = kernel::KernelOptions::defaults(*options.kernel);
    kernel_options.max_range = options.max_range_m;
    kind_ = makeKernelKind(std::move(map), kernel_options);
  } else {
    kind_ = makeLogOddsKind(
        std::move(map),
        {.method = options.method, .rule = options.rule, .max_range_m = options.max_range_m});
  }
  kind_->published().startVersionsAt(version);
  kind_->published().reserveBlocks(options.reserve_blocks);
  view_.store(MapView::publish(kind_->published()));
  // The graph belongs to the pipeline's arena: build it there.
  arena_.execute([this] { graph_ = std::make_unique<Graph>(*this); });
  if (options.warm_up) arena_.execute([this] { kind_->warmUp(options_.max_range_m); });
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
    state.kernel = kind_->evidence();
    return std::string();
  });
  done.wait();
  return state;
}

Expected<void> Pipeline::restoreKernelEvidence(const kernel::KernelEvidence& evidence) {
  if (running_.load()) return makeError("kernel evidence is restored before start()");
  return kind_->restore(evidence);
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
    arena_.execute([&] { outcome = kind_->command(command, result.changes); });
    if (!result.changes.empty()) publish(result);
    promise.set_value(std::move(outcome));
  }
}

void Pipeline::publish(IntegrationResult& result) {
  kind_->beforePublish(result.changes);
  result.base_version = view_.load()->version();
  // A mirror follows the octree cell for cell, so its known-cell count is the map's.
  auto next = MapView::publish(kind_->published(), kind_->ownBytes(), &result.written_blocks);
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
  // create() refuses eviction unless the map is the grid itself (no mirror).
  if ((options_.keep_radius_m <= 0 && !options_.bounds) || !kind_->canEvict()) return;
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
  const EvictStats stats = kind_->evict(keep, changes);
  result.evicted_blocks = stats.blocks;
  result.evicted_cells = stats.cells;
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
