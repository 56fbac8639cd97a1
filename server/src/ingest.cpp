#include "densemap/server/ingest.hpp"

#include <algorithm>
#include <chrono>

#include "densemap/parallel/tbb_runner.hpp"

#include "densemap/geometry/percentile.hpp"
#include "guarded.hpp"
#include "ingest_background.hpp"

namespace densemap::server {

Expected<std::unique_ptr<Ingest>> Ingest::create(const IngestOptions& options,
                                                 std::unique_ptr<OccupancyMap> initial,
                                                 std::uint64_t initial_version) {
  if (options.threads < 1 || options.threads > 256) return makeError("threads must be in 1..256");
  if (options.queue_depth < 1 || options.queue_depth > 1024) {
    return makeError("queue depth must be in 1..1024");
  }
  auto engine = Engine::create(options.engine, std::move(initial), initial_version);
  if (!engine) return std::unexpected(engine.error());
  std::optional<DistanceField> field;
  if (options.distance_field) {
    auto f = DistanceField::create(options.engine.resolution_m, *options.distance_field);
    if (!f) return makeError("esdf: " + f.error().message);
    field = std::move(*f);
  }
  if (options.history_threads < 1 || options.history_threads > 256) {
    return makeError("history threads must be in 1..256");
  }
  std::unique_ptr<ScanHistory> history;
  if (options.history) {
    if (options.engine.kernel || options.engine.decay) {
      return makeError("history: pose corrections need a log_odds map without map.decay");
    }
    auto h = ScanHistory::create(*options.history, (*engine)->view());
    if (!h) return std::unexpected(h.error());
    history = std::move(*h);
  }
  auto ingest = std::unique_ptr<Ingest>(new Ingest(options, std::move(*engine)));
  ingest->history_ = std::move(history);
  ingest->history_status_.enabled = ingest->history_ != nullptr;
  if (field) {
    ingest->field_ = std::move(field);
    ingest->field_view_ = ingest->engine_->view();
    ingest->arena_.execute([&] { ingest->field_->rebuild(*ingest->field_view_, tbbRunner()); });
  }
  return ingest;
}

Ingest::Ingest(const IngestOptions& options, std::unique_ptr<Engine> engine)
    : options_(engine->options()),
      engine_(std::move(engine)),
      arena_(options.threads),
      history_arena_(options.history_threads),
      queue_(
          options.queue_depth, options.queue_depth * kQueueSensorShare,
          [](const RawScan& scan) -> const std::string& { return scan.sensor_id; },
          SensorTally::kMaxSensors, rawScanBytes, options.queue_budget_bytes) {
  if (options.engine.warm_up) arena_.execute([this] { engine_->warmUp(); });
  latest_.view = engine_->view();
}

Ingest::~Ingest() { stop(); }

void Ingest::start() {
  if (running_.exchange(true)) return;
  worker_ = std::thread([this] { run(); });
}

void Ingest::stop() {
  if (!running_.exchange(false)) return;
  const auto discarded = queue_.close();
  {
    std::lock_guard lock(counters_mutex_);
    for (const RawScan& scan : discarded) sensors_.dropped(scan.sensor_id);
  }
  if (worker_.joinable()) worker_.join();
  cancelReintegration();
  runCommands();  // commands queued while stopping (e.g. the shutdown snapshot) still run
}

void Ingest::submit(RawScan scan) {
  if (auto ok = checkSensorId(scan.sensor_id); !ok) {
    // Counted and reported under the id's first kMaxSensorIdBytes bytes: the whole id is
    // neither kept nor echoed.
    scan.sensor_id.resize(kMaxSensorIdBytes);
    {
      std::lock_guard lock(counters_mutex_);
      ++counters_.received;
      sensors_.received(scan.sensor_id, scan.seq);
    }
    rejected(scan, ok.error());
    return;
  }
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

std::future<Expected<std::string>> Ingest::command(Command command) {
  std::promise<Expected<std::string>> promise;
  auto future = promise.get_future();
  {
    std::lock_guard lock(commands_mutex_);
    commands_.emplace_back(std::move(command), std::move(promise));
  }
  if (!running_.load()) runCommands();
  return future;
}

Ingest::SavedState Ingest::savedState() {
  SavedState state;
  // A command with no changes publishes nothing: the view it reads is the latest published,
  // the one the kernel map's evidence stands behind.
  auto done = command([&](OccupancyMap&, CellChanges&) -> Expected<std::string> {
    state.view = engine_->view();
    state.kernel = engine_->evidence();
    return std::string();
  });
  done.wait();
  return state;
}

Expected<void> Ingest::restoreKernelEvidence(const kernel::KernelEvidence& evidence) {
  if (running_.load()) return makeError("kernel evidence is restored before start()");
  return engine_->restore(evidence);
}

void Ingest::run() {
  while (running_.load()) {
    // process() and runCommands() turn the engine's failures into rejections and errors;
    // guarded() takes the rest (a counter's allocation, a reject handler).
    guarded("ingest", [&] {
      runCommands();
      applyCatchUp();
      applyCorrections();
      finishReintegration();
      auto raw = queue_.pop(std::chrono::milliseconds(20));
      if (raw) process(*raw);
    });
  }
}

std::expected<IntegrationResult, Rejection> Ingest::integrate(const RawScan& raw) {
  std::expected<IntegrationResult, Rejection> outcome;
  try {
    arena_.execute([&] { outcome = engine_->integrate(raw); });
  } catch (...) {
    // Nothing is published: readers keep the last version. The map is not rolled back, so a
    // scan that failed part-way may leave part of its update, published with the next scan.
    return std::unexpected(
        Rejection{RejectReason::kInternal, "integration failed: " + cli::currentFailure()});
  }
  return outcome;
}

void Ingest::process(const RawScan& raw) {
  std::expected<IntegrationResult, Rejection> outcome = integrate(raw);
  if (outcome) {
    outcome->latency_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - raw.received)
            .count();
    recordScan(raw);
    keepForCatchUp(raw);
    published(*outcome);
    return;
  }
  rejected(raw, outcome.error());
}

void Ingest::rejected(const RawScan& raw, const Rejection& rejection) {
  {
    std::lock_guard lock(counters_mutex_);
    ++counters_.rejected;
    ++counters_.rejected_by_reason[static_cast<std::size_t>(rejection.reason)];
    sensors_.rejected(raw.sensor_id);
    counters_.last_reject_reason = rejection.message;
  }
  if (on_reject_) on_reject_(raw, rejection);
}

void Ingest::runCommands() {
  std::vector<std::pair<Command, std::promise<Expected<std::string>>>> pending;
  {
    std::lock_guard lock(commands_mutex_);
    pending.swap(commands_);
  }
  for (auto& [command, promise] : pending) {
    IntegrationResult result;
    Expected<std::string> outcome;
    try {
      arena_.execute([&] { outcome = engine_->command(command, result); });
      if (!result.changes.empty()) {
        restartHistory();  // the scans before it no longer make the map
        published(result);
      }
    } catch (...) {
      outcome = makeError("command failed: " + cli::currentFailure());
    }
    promise.set_value(std::move(outcome));
  }
}

void Ingest::published(IntegrationResult& result) {
  // The distance field follows the version before it is announced: a distance query reads the
  // field with the view it was updated to.
  if (field_) {
    auto view = engine_->view();
    const std::unique_lock lock(field_mutex_);
    bool updated = false;
    guarded("ingest: updating the distance field", [&] {
      arena_.execute([&] { field_->update(*view, result.written_blocks, tbbRunner()); });
      updated = true;
    });
    // An update cut short (out of memory) leaves the field unknown: build it anew.
    if (!updated) {
      guarded("ingest: rebuilding the distance field",
              [&] { arena_.execute([&] { field_->rebuild(*view, tbbRunner()); }); });
    }
    field_view_ = std::move(view);
  }
  if (result.from_scan) {
    std::lock_guard lock(counters_mutex_);
    ++counters_.integrated;
    counters_.evicted_blocks += result.evicted_blocks;
    counters_.evicted_cells += result.evicted_cells;
    counters_.decayed_cells += result.decayed.erased;
    sensors_.integrated(result.sensor_id, result.latency_ms);
    if (latencies_.size() < 1024) {
      latencies_.push_back(result.latency_ms);
    } else {
      latencies_[latency_next_] = result.latency_ms;
      latency_next_ = (latency_next_ + 1) % latencies_.size();
    }
  }
  if (result.from_scan) {
    const auto it = std::find_if(last_stamps_.begin(), last_stamps_.end(),
                                 [&](const auto& s) { return s.first == result.sensor_id; });
    if (it != last_stamps_.end()) {
      it->second = result.stamp_ns;
    } else if (last_stamps_.size() < SensorTally::kMaxSensors) {
      last_stamps_.emplace_back(result.sensor_id, result.stamp_ns);
    }
  }
  {
    std::lock_guard lock(latest_mutex_);
    latest_ = {engine_->view(), last_stamps_};
  }
  // A publisher that throws loses the announcement; the version is published (readers see it).
  if (publisher_)
    guarded("ingest: announcing a version", [&] { publisher_(result, engine_->view()); });
}

PipelineCounters Ingest::counters() const {
  std::lock_guard lock(counters_mutex_);
  PipelineCounters c = counters_;
  c.dropped = queue_.dropped();
  c.sensors = sensors_.sensors();
  c.history = history_status_;
  if (history_) {
    const ScanStore& store = history_->store();
    c.history.scans = store.end() - store.first();
    c.history.bytes = store.bytes();
  }
  if (!latencies_.empty()) {
    std::vector<double> v = latencies_;
    std::sort(v.begin(), v.end());
    c.latency_p50_ms = nearestRank(v, 0.5);
    c.latency_p99_ms = nearestRank(v, 0.99);
  }
  return c;
}

}  // namespace densemap::server
