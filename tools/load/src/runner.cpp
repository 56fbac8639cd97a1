#include "densemap/load/runner.hpp"

#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <unordered_map>

#include "children.hpp"
#include "densemap/io/process_usage.hpp"
#include "streams.hpp"

namespace densemap::load {

using namespace detail;  // the streams (streams.hpp) and child processes (children.hpp)

Expected<void> prepareData(const Scenario& scenario, const std::filesystem::path& work_dir) {
  for (const SensorPlan& p : scenario.sensors) {
    auto source = openData(p, work_dir);
    if (!source) return std::unexpected(source.error());
  }
  return {};
}

int runChildClient(const Scenario& scenario, std::size_t index, Clock::time_point epoch,
                   const std::filesystem::path& tracks_file, const std::filesystem::path& out,
                   const RunOptions& options) {
  QueryResult result;
  result.name = index < scenario.clients.size() ? scenario.clients[index].name : "?";
  auto tracks = readTracks(tracks_file);
  if (index >= scenario.clients.size() || !tracks) {
    result.last_error = !tracks ? tracks.error().message : "no such client";
    writeChildResult(out, result);
    return 2;
  }
  const ClientPlan& plan = scenario.clients[index];
  const Track none;
  const Track& track = plan.around_sensor < tracks->size() ? (*tracks)[plan.around_sensor] : none;
  auto client = connect(options.client);
  if (!client) {
    result.last_error = client.error().message;
    writeChildResult(out, result);
    return 1;
  }
  std::atomic<bool> stop{false};
  runQueries(**client, plan, index, track, epoch, scenario.duration_s, stop, result);
  writeChildResult(out, result);
  return 0;
}

namespace {

/// One run of a scenario, in stages: connect every participant before the clock starts, run
/// the senders, query clients and late joiners on their threads while observing the map's
/// events and the server's usage, drain, then the server's counts per stream.
class ScenarioRun {
 public:
  ScenarioRun(const Scenario& scenario, const RunOptions& options)
      : scenario_(scenario),
        options_(options),
        run_dir_(options.work_dir / ("run-" + std::to_string(getpid()))) {
    result_.scenario = scenario.name;
    result_.duration_s = scenario.duration_s;
    result_.sensors.resize(scenario.sensors.size());
    result_.clients.resize(scenario.clients.size());
    for (std::size_t i = 0; i < scenario.sensors.size(); ++i) {
      result_.sensors[i].sensor_id = scenario.sensors[i].sensor_id;
      sensor_index_[scenario.sensors[i].sensor_id] = i;
    }
    for (std::size_t i = 0; i < scenario.clients.size(); ++i) {
      result_.clients[i].name = scenario.clients[i].name;
    }
  }
  ~ScenarioRun() {
    stop_ = true;
    for (auto& t : threads_) {
      if (t.joinable()) t.join();
    }
    std::error_code ec;
    std::filesystem::remove_all(run_dir_, ec);
  }
  ScenarioRun(const ScenarioRun&) = delete;
  ScenarioRun& operator=(const ScenarioRun&) = delete;

  /// Every participant is made and matched before the clock starts, so discovery is not
  /// measured as latency. Child processes get a start time far enough out to do the same.
  Expected<void> connectAll() {
    std::error_code ec;
    std::filesystem::create_directories(options_.work_dir, ec);
    auto data = preload(scenario_, options_.work_dir);
    if (!data) return std::unexpected(data.error());
    data_ = std::move(*data);
    tracks_ = tracksOf(scenario_, data_, options_.work_dir);
    auto observer = connect(options_.client);
    if (!observer) return std::unexpected(observer.error());
    observer_ = std::move(*observer);
    for (const SensorPlan& p : scenario_.sensors) {
      auto c = connect(options_.client);
      if (!c) return makeError("sensor " + p.sensor_id + ": " + c.error().message);
      senders_.push_back(std::move(*c));
    }
    if (options_.processes) {
      std::filesystem::create_directories(run_dir_, ec);
      writeTracks(run_dir_ / "tracks.txt", tracks_);
      epoch_ = Clock::now() + std::chrono::seconds(3) +
               std::chrono::milliseconds(100) * scenario_.clients.size();
      return children_.spawn(options_, scenario_, epoch_, run_dir_ / "tracks.txt", run_dir_);
    }
    for (const ClientPlan& p : scenario_.clients) {
      auto c = connect(options_.client);
      if (!c) return makeError("query client " + p.name + ": " + c.error().message);
      queriers_.push_back(std::move(*c));
    }
    epoch_ = Clock::now() + std::chrono::milliseconds(200);
    return {};
  }

  /// The server's status before the clock starts, then every stream on its thread.
  Expected<void> start() {
    auto before = observer_->status();
    if (!before) return std::unexpected(before.error());
    result_.before = *before;
    newest_version_ = before->map_version;
    for (std::size_t i = 0; i < senders_.size(); ++i) {
      const Dataset& d = *data_.at(datasetKey(scenario_.sensors[i], options_.work_dir));
      threads_.emplace_back([this, i, &d] {
        runSensor(*senders_[i], scenario_.sensors[i], i, d, epoch_, scenario_.duration_s,
                  in_flight_, stop_, result_.sensors[i]);
      });
    }
    for (std::size_t i = 0; i < queriers_.size(); ++i) {
      threads_.emplace_back([this, i] {
        static const Track kNone;
        const ClientPlan& p = scenario_.clients[i];
        const Track& t = p.around_sensor < tracks_.size() ? tracks_[p.around_sensor] : kNone;
        runQueries(*queriers_[i], p, i, t, epoch_, scenario_.duration_s, stop_, result_.clients[i]);
      });
    }
    if (!scenario_.joiner_times_s.empty()) threads_.emplace_back([this] { runJoiners(); });
    return {};
  }

  /// The observer until the end time: map events (end-to-end latency), a usage sample every
  /// second, a progress line every 5 s.
  void observe() {
    (void)sleepUntil(epoch_, stop_);  // stopped only by the destructor
    sample();
    double next_progress = 5.0;
    while (secondsSince(epoch_) < scenario_.duration_s) {
      poll();
      const double now = secondsSince(epoch_);
      if (now >= next_sample_) {
        sample();
        next_sample_ += 1.0;
      }
      if (options_.progress && now >= next_progress) {
        std::uint64_t sent = 0, seen = 0;
        for (const auto& s : result_.sensors) sent += s.sent, seen += s.seen;
        std::fprintf(stderr, "load: %s %.0f/%.0f s, scans sent %llu, integrated and seen %llu\n",
                     scenario_.name.c_str(), now, scenario_.duration_s,
                     static_cast<unsigned long long>(sent), static_cast<unsigned long long>(seen));
        next_progress += 5.0;
      }
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
  }

  /// Senders and clients stop at the end time (late joiners are cut short); then events until
  /// every scan sent is seen or counted dropped/rejected, or 3 s without news (at most 15).
  void drain() {
    stop_ = true;
    for (auto& t : threads_) t.join();
    threads_.clear();
    children_.collect(std::chrono::seconds(15), result_.clients);
    const double drain_start = secondsSince(epoch_);
    last_event_s_ = std::max(last_event_s_, drain_start);
    while (secondsSince(epoch_) - last_event_s_ < 3.0 &&
           secondsSince(epoch_) - drain_start < 15.0) {
      poll();
      if (secondsSince(epoch_) >= next_sample_) {
        sample();
        next_sample_ += 1.0;
        if (accounted()) break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // one more status period
    sample();
  }

  /// The server's counts per stream: the difference over the run.
  RunResult finish() {
    for (auto& s : result_.sensors) {
      s.server.sensor_id = s.sensor_id;
      for (const SensorCounters& c : result_.after.sensors) {
        if (c.sensor_id != s.sensor_id) continue;
        s.server = c;
        const SensorCounters* b = before(c.sensor_id);
        if (b == nullptr) continue;
        s.server.received -= std::min(s.server.received, b->received);
        s.server.integrated -= std::min(s.server.integrated, b->integrated);
        s.server.dropped -= std::min(s.server.dropped, b->dropped);
        s.server.rejected -= std::min(s.server.rejected, b->rejected);
        s.server.seq_gaps -= std::min(s.server.seq_gaps, b->seq_gaps);
      }
    }
    return std::move(result_);
  }

 private:
  void runJoiners() {
    for (const double t : scenario_.joiner_times_s) {
      if (t >= scenario_.duration_s || !sleepUntil(at(epoch_, t), stop_)) break;
      JoinerResult j;
      j.at_s = secondsSince(epoch_);
      auto client = connect(options_.client);
      if (client) {
        auto map = (*client)->fetchMap();
        if (map) {
          j.cells = map->knownCells();
          j.version = map->version();
        } else {
          j.error = map.error().message;
        }
      } else {
        j.error = client.error().message;
      }
      j.seconds = secondsSince(epoch_) - j.at_s;
      const std::uint64_t newest = newest_version_.load();
      j.versions_behind = newest > j.version && j.error.empty() ? newest - j.version : 0;
      result_.joiners.push_back(std::move(j));
    }
  }

  void sample() {
    UsageSample u;
    u.t_s = secondsSince(epoch_);
    if (auto s = observer_->status(); s) {
      u.server_cpu_s = s->cpu_s;
      u.server_rss = s->rss_bytes;
      u.known_cells = s->known_cells;
      u.map_version = s->map_version;
      u.map_bytes = s->memory_bytes;
      u.integrated = s->integrated;
      u.dropped = s->dropped;
      u.rejected = s->rejected;
      result_.after = *s;
    }
    u.load_cpu_s = processUsage().cpu_s + children_.cpuSeconds();
    const MachineCpu m = machineCpu();
    u.machine_busy_s = m.busy_s;
    u.machine_total_s = m.total_s;
    result_.usage.push_back(u);
  }

  void poll() {
    observer_->pollEvents([&](const MapEventInfo& e) {
      newest_version_ = std::max(newest_version_.load(), e.new_version);
      if (!e.from_scan) return;
      const auto it = sensor_index_.find(e.sensor_id);
      if (it == sensor_index_.end()) return;
      if (const auto sent = in_flight_.seen(it->second, e.scan_seq)) {
        const double now = secondsSince(epoch_);
        auto& s = result_.sensors[it->second];
        ++s.seen;
        s.e2e.push_back({*sent, (now - *sent) * 1000.0});
        last_event_s_ = now;
      }
    });
  }

  /// A sensor's counters in the status before the run (none: it is new).
  [[nodiscard]] const SensorCounters* before(const std::string& sensor_id) const {
    for (const SensorCounters& b : result_.before.sensors) {
      if (b.sensor_id == sensor_id) return &b;
    }
    return nullptr;
  }

  /// Whether every scan sent is seen or counted lost (dropped or rejected) by the server.
  [[nodiscard]] bool accounted() const {
    for (const auto& s : result_.sensors) {
      std::uint64_t lost = 0;
      for (const SensorCounters& c : result_.after.sensors) {
        if (c.sensor_id != s.sensor_id) continue;
        lost = c.dropped + c.rejected;
        if (const SensorCounters* b = before(c.sensor_id)) {
          lost -= std::min(lost, b->dropped + b->rejected);
        }
      }
      if (s.seen + lost < s.sent) return false;
    }
    return true;
  }

  const Scenario& scenario_;
  const RunOptions& options_;
  const std::filesystem::path run_dir_;
  RunResult result_;
  std::map<std::string, std::shared_ptr<const Dataset>> data_;
  std::vector<Track> tracks_;
  std::unique_ptr<Client> observer_;
  std::vector<std::unique_ptr<Client>> senders_, queriers_;
  Children children_;
  Clock::time_point epoch_;
  std::unordered_map<std::string, std::size_t> sensor_index_;
  std::atomic<bool> stop_{false};
  InFlight in_flight_;
  std::vector<std::thread> threads_;
  std::atomic<std::uint64_t> newest_version_{0};
  double last_event_s_ = 0, next_sample_ = 1.0;
};

}  // namespace

Expected<RunResult> runScenario(const Scenario& scenario, const RunOptions& options) {
  ScenarioRun run(scenario, options);
  if (auto ok = run.connectAll(); !ok) return std::unexpected(ok.error());
  if (auto ok = run.start(); !ok) return std::unexpected(ok.error());
  run.observe();
  run.drain();
  return run.finish();
}

}  // namespace densemap::load
