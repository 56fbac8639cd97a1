#include "densemap/load/runner.hpp"

#include <spawn.h>
#include <sys/wait.h>
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

#include "densemap/io/process_usage.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/sim/sequence.hpp"

extern char** environ;

namespace densemap::load {
namespace {

/// Preloaded scans stay under this many bytes in all: a load generator that reads files while
/// it measures would compete with the server for the same cores.
constexpr std::size_t kPreloadBudget = std::size_t{3} << 30;

double secondsSince(Clock::time_point epoch) {
  return std::chrono::duration<double>(Clock::now() - epoch).count();
}

Clock::time_point at(Clock::time_point epoch, double s) {
  return epoch + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

/// Sleeps until `t` or until `stop`, in short steps; false when stopped first.
bool sleepUntil(Clock::time_point t, const std::atomic<bool>& stop) {
  while (Clock::now() < t) {
    if (stop.load()) return false;
    std::this_thread::sleep_for(
        std::min<Clock::duration>(t - Clock::now(), std::chrono::milliseconds(20)));
  }
  return !stop.load();
}

std::filesystem::path dataPath(const SensorPlan& p, const std::filesystem::path& work_dir) {
  return p.sim ? simDatasetDir(*p.sim, work_dir) : p.data;
}

/// Streams that replay the same part of the same dataset share one preloaded copy.
std::string datasetKey(const SensorPlan& p, const std::filesystem::path& work_dir) {
  return dataPath(p, work_dir).string() + "#" + std::to_string(p.first) + "+" +
         std::to_string(p.limit);
}

/// A dataset's scans as a sender publishes them (sensor frame, pose as given).
struct Dataset {
  std::vector<RawScan> scans;
};

Expected<std::unique_ptr<ScanSource>> openData(const SensorPlan& p,
                                               const std::filesystem::path& work_dir) {
  const auto dir = dataPath(p, work_dir);
  if (p.sim && !std::filesystem::exists(dir / "poses.txt")) {
    std::fprintf(stderr, "load: simulating %d %s scans of '%s' into %s\n", p.sim->scans,
                 p.sim->sensor.c_str(), p.sim->scene.c_str(), dir.string().c_str());
    auto written = writeSimulatedSequence(*p.sim, dir);
    if (!written) return std::unexpected(written.error());
  }
  return openScanSource(dir);
}

/// Where a stream's sensor is at each of its scans (world frame, offset applied).
struct Track {
  std::vector<Point3f> origins;
  double rate_hz = 10, start_s = 0;
  bool loop = true;

  [[nodiscard]] Point3f at(double t_s) const {
    if (origins.empty()) return Point3f::Zero();
    const auto i = static_cast<std::size_t>(std::max(0.0, (t_s - start_s) * rate_hz));
    return origins[loop ? i % origins.size() : std::min(i, origins.size() - 1)];
  }
};

RawScan withOffset(const RawScan& scan, const Transform& offset) {
  RawScan out = scan;
  const Eigen::Vector3d t = offset * Eigen::Vector3d(scan.t_world_sensor[0], scan.t_world_sensor[1],
                                                     scan.t_world_sensor[2]);
  const Eigen::Quaterniond q = Eigen::Quaterniond(offset.linear()) *
                               Eigen::Quaterniond(scan.q_world_sensor[0], scan.q_world_sensor[1],
                                                  scan.q_world_sensor[2], scan.q_world_sensor[3]);
  out.t_world_sensor = {t.x(), t.y(), t.z()};
  out.q_world_sensor = {q.w(), q.x(), q.y(), q.z()};
  return out;
}

Expected<std::map<std::string, std::shared_ptr<const Dataset>>> preload(
    const Scenario& scenario, const std::filesystem::path& work_dir) {
  std::map<std::string, std::shared_ptr<const Dataset>> out;
  std::size_t bytes = 0;
  for (const SensorPlan& p : scenario.sensors) {
    const std::string key = datasetKey(p, work_dir);
    if (out.count(key) != 0) continue;
    auto source = openData(p, work_dir);
    if (!source) return std::unexpected(source.error());
    const std::size_t n = (*source)->size();
    if (p.first >= n) {
      return makeError(p.sensor_id + ": first " + std::to_string(p.first) + " but " +
                       (*source)->describe() + " has " + std::to_string(n) + " scans");
    }
    const std::size_t end = p.limit == 0 ? n : std::min(n, p.first + p.limit);
    auto data = std::make_shared<Dataset>();
    for (std::size_t i = p.first; i < end; ++i) {
      auto scan = (*source)->load(i);
      if (!scan) return std::unexpected(scan.error());
      data->scans.push_back(toRawScan(*scan, 0, p.sensor_id));
      bytes += data->scans.back().xyz.size() * sizeof(float);
      if (bytes > kPreloadBudget) {
        return makeError(
            "the scenario's datasets exceed the load tool's preload budget of 3 GiB "
            "(at " +
            (*source)->describe() + " scan " + std::to_string(i) + "); set a limit on the streams");
      }
    }
    out.emplace(key, std::move(data));
  }
  return out;
}

std::vector<Track> tracksOf(const Scenario& scenario,
                            const std::map<std::string, std::shared_ptr<const Dataset>>& data,
                            const std::filesystem::path& work_dir) {
  std::vector<Track> tracks;
  for (const SensorPlan& p : scenario.sensors) {
    const auto& d = *data.at(datasetKey(p, work_dir));
    Track t{{}, p.rate_hz, p.start_offset_s, p.loop};
    for (const RawScan& s : d.scans) {
      const Eigen::Vector3d o =
          p.offset * Eigen::Vector3d(s.t_world_sensor[0], s.t_world_sensor[1], s.t_world_sensor[2]);
      t.origins.emplace_back(o.cast<float>());
    }
    tracks.push_back(std::move(t));
  }
  return tracks;
}

void writeTracks(const std::filesystem::path& file, const std::vector<Track>& tracks) {
  std::ofstream out(file);
  for (const Track& t : tracks) {
    out << "track " << t.rate_hz << ' ' << t.start_s << ' ' << (t.loop ? 1 : 0) << ' '
        << t.origins.size() << '\n';
    for (const Point3f& o : t.origins) out << o.x() << ' ' << o.y() << ' ' << o.z() << '\n';
  }
}

Expected<std::vector<Track>> readTracks(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return makeError("cannot read " + file.string());
  std::vector<Track> tracks;
  std::string word;
  while (in >> word) {
    Track t;
    std::size_t n = 0;
    int loop = 1;
    if (word != "track" || !(in >> t.rate_hz >> t.start_s >> loop >> n) || n > 10'000'000) {
      return makeError(file.string() + ": not a track file");
    }
    t.loop = loop != 0;
    for (std::size_t i = 0; i < n; ++i) {
      float x = 0, y = 0, z = 0;
      if (!(in >> x >> y >> z)) return makeError(file.string() + ": truncated");
      t.origins.emplace_back(x, y, z);
    }
    tracks.push_back(std::move(t));
  }
  return tracks;
}

Expected<std::unique_ptr<Client>> connect(const ClientOptions& o) {
  auto client = Client::create(o);
  if (!client) return client;
  if (auto ok = (*client)->waitForServer(); !ok) return std::unexpected(ok.error());
  return client;
}

/// Send times of scans in flight, shared by the senders and the event reader.
class InFlight {
 public:
  void sent(std::size_t sensor, std::uint64_t seq, double t_s) {
    std::lock_guard lock(mutex_);
    times_[key(sensor, seq)] = t_s;
  }
  /// The send time of a scan whose event arrived, forgotten once returned.
  std::optional<double> seen(std::size_t sensor, std::uint64_t seq) {
    std::lock_guard lock(mutex_);
    const auto it = times_.find(key(sensor, seq));
    if (it == times_.end()) return std::nullopt;
    const double t = it->second;
    times_.erase(it);
    return t;
  }

 private:
  static std::uint64_t key(std::size_t sensor, std::uint64_t seq) {
    return (static_cast<std::uint64_t>(sensor) << 48) | (seq & ((1ULL << 48) - 1));
  }
  std::mutex mutex_;
  std::unordered_map<std::uint64_t, double> times_;
};

void runSensor(Client& client, const SensorPlan& plan, std::size_t index, const Dataset& data,
               Clock::time_point epoch, double duration_s, InFlight& in_flight,
               const std::atomic<bool>& stop, SensorResult& out) {
  const double period = 1.0 / plan.rate_hz;
  double next = plan.start_offset_s;
  std::uint64_t seq = 1;
  for (std::size_t i = 0; next < duration_s; ++i, next += period) {
    if (!plan.loop && i >= data.scans.size()) break;
    if (!sleepUntil(at(epoch, next), stop)) break;
    if (secondsSince(epoch) > next + period) ++out.late_sends;
    RawScan scan = withOffset(data.scans[i % data.scans.size()], plan.offset);
    scan.sensor_id = plan.sensor_id;
    scan.seq = seq++;
    scan.stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count();
    in_flight.sent(index, scan.seq, secondsSince(epoch));
    if (client.publishScan(scan)) ++out.sent;
  }
}

/// Point batches, boxes and rays around where the tracked sensor is at the time of asking.
void runQueries(Client& client, const ClientPlan& plan, std::size_t index, const Track& track,
                Clock::time_point epoch, double duration_s, const std::atomic<bool>& stop,
                QueryResult& out) {
  std::mt19937_64 rng(0x5eed + index);
  std::discrete_distribution<int> pick(std::begin(plan.weights), std::end(plan.weights));
  std::uniform_real_distribution<float> unit(-1.0F, 1.0F);
  const double period = plan.rate_hz > 0 ? 1.0 / plan.rate_hz : 0.0;
  double next = 0;
  const float spread = static_cast<float>(plan.spread_m);
  std::vector<Point3f> points(plan.point_batch);
  for (std::uint64_t n = 0; n < plan.max_requests; ++n) {
    if (period > 0) {
      if (!sleepUntil(at(epoch, next), stop)) break;
      next += period;
      if (secondsSince(epoch) > next + 1.0) {  // more than a second behind: skip ticks
        const double behind = secondsSince(epoch) - next;
        const auto skipped = static_cast<std::uint64_t>(behind / period);
        out.late_ticks += skipped;
        next += static_cast<double>(skipped) * period;
      }
    }
    const double t = secondsSince(epoch);
    if (t >= duration_s || stop.load()) break;
    const Point3f c = track.at(t);
    const int kind = pick(rng);
    const auto t0 = Clock::now();
    Expected<void> ok;
    if (kind == static_cast<int>(QueryKind::kPoint)) {
      for (Point3f& p : points) {
        p = c + Point3f(unit(rng) * spread, unit(rng) * spread, unit(rng) * 2.0F);
      }
      auto a = client.queryPoints(points);
      if (!a) ok = std::unexpected(a.error());
    } else if (kind == static_cast<int>(QueryKind::kBox)) {
      const Point3f half = Point3f::Constant(static_cast<float>(plan.bbox_edge_m / 2));
      auto a = client.queryBox(c - half, c + half);
      if (!a) ok = std::unexpected(a.error());
    } else {
      const Point3f origin = c + Point3f(unit(rng) * spread, unit(rng) * spread, 0.0F);
      Point3f dir(unit(rng), unit(rng), 0.2F * unit(rng));
      if (dir.norm() < 1e-3F) dir = Point3f::UnitX();
      auto a = client.castRay(origin, dir.normalized(), static_cast<float>(plan.ray_range_m));
      if (!a) ok = std::unexpected(a.error());
    }
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (ok) {
      ++out.answered[kind];
      out.latency[kind].push_back({t, ms});
    } else {
      ++out.failed[kind];
      if (ok.error().message.find("no reply") != std::string::npos) ++out.timeouts[kind];
      out.last_error = ok.error().message;
    }
  }
}

void writeChildResult(const std::filesystem::path& file, const QueryResult& r) {
  std::ofstream out(file);
  out << "late " << r.late_ticks << "\ncpu " << processUsage().cpu_s << '\n';
  for (int k = 0; k < kQueryKinds; ++k) {
    out << "count " << k << ' ' << r.failed[k] << ' ' << r.timeouts[k] << '\n';
    for (const Timed& s : r.latency[k]) out << "q " << k << ' ' << s.t_s << ' ' << s.ms << '\n';
  }
  if (!r.last_error.empty()) out << "error " << r.last_error << '\n';
}

void readChildResult(const std::filesystem::path& file, QueryResult& r) {
  std::ifstream in(file);
  std::string word;
  while (in >> word) {
    if (word == "late") {
      in >> r.late_ticks;
    } else if (word == "cpu") {
      in >> r.cpu_s;
    } else if (word == "count") {
      int k = 0;
      in >> k;
      if (k < 0 || k >= kQueryKinds) return;
      in >> r.failed[k] >> r.timeouts[k];
    } else if (word == "q") {
      int k = 0;
      Timed s;
      in >> k >> s.t_s >> s.ms;
      if (k < 0 || k >= kQueryKinds) return;
      r.latency[k].push_back(s);
      ++r.answered[k];
    } else if (word == "error") {
      std::getline(in, r.last_error);
    } else {
      return;
    }
  }
}

/// Child processes running query clients (--processes).
class Children {
 public:
  Expected<void> spawn(const RunOptions& o, const Scenario& scenario, Clock::time_point epoch,
                       const std::filesystem::path& tracks, const std::filesystem::path& dir) {
    const auto epoch_ns =
        std::chrono::duration_cast<std::chrono::nanoseconds>(epoch.time_since_epoch()).count();
    for (std::size_t i = 0; i < scenario.clients.size(); ++i) {
      outs_.push_back(dir / ("client-" + std::to_string(i) + ".txt"));
      std::vector<std::string> args = {o.self_exe.string()};
      args.insert(args.end(), o.child_args.begin(), o.child_args.end());
      for (const std::string& a :
           {std::string("--child-client"), std::to_string(i), std::string("--child-epoch-ns"),
            std::to_string(epoch_ns), std::string("--child-out"), outs_.back().string(),
            std::string("--child-tracks"), tracks.string()}) {
        args.push_back(a);
      }
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      pid_t pid = 0;
      if (posix_spawn(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0) {
        stop();
        return makeError("cannot start a query-client process (" + o.self_exe.string() + ")");
      }
      pids_.push_back(pid);
    }
    return {};
  }
  /// Their CPU time so far, from /proc (while they run; their own final figure comes in their
  /// result files). Each child's figure never goes back: a child that has exited reads as 0 in
  /// /proc, which made the load tool's CPU share negative (issue 28, item 10: "-115 %").
  double cpuSeconds() {
    last_cpu_s_.resize(pids_.size(), 0.0);
    double s = 0;
    for (std::size_t i = 0; i < pids_.size(); ++i) {
      last_cpu_s_[i] = std::max(last_cpu_s_[i], processUsage(pids_[i]).cpu_s);
      s += last_cpu_s_[i];
    }
    return s;
  }
  /// Waits for every child (killing those still running `grace` later) and reads results.
  void collect(std::chrono::seconds grace, std::vector<QueryResult>& results) {
    const auto deadline = Clock::now() + grace;
    for (std::size_t i = 0; i < pids_.size(); ++i) {
      int status = 0;
      while (waitpid(pids_[i], &status, WNOHANG) == 0) {
        if (Clock::now() > deadline) {
          kill(pids_[i], SIGKILL);
          waitpid(pids_[i], &status, 0);
          results[i].last_error = "the client process did not finish in time and was killed";
          break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
      // A client whose process failed (exit status, or no result file: it never got to
      // write one) did not run: counted, never reported as "failed 0".
      const bool wrote = std::filesystem::exists(outs_[i]);
      readChildResult(outs_[i], results[i]);
      const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
      if (!wrote || !ok) {
        results[i].started = false;
        if (results[i].last_error.empty()) {
          results[i].last_error = "the client process failed to start or run (" +
                                  std::string(!wrote ? "no result" : "exit status") + ")";
        }
      }
    }
    pids_.clear();
    last_cpu_s_.clear();
  }
  void stop() {
    for (const pid_t pid : pids_) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
    pids_.clear();
  }
  ~Children() { stop(); }

 private:
  std::vector<pid_t> pids_;
  std::vector<std::filesystem::path> outs_;
  std::vector<double> last_cpu_s_;  // per child, the most CPU seen
};

}  // namespace

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

Expected<RunResult> runScenario(const Scenario& scenario, const RunOptions& options) {
  std::error_code ec;
  std::filesystem::create_directories(options.work_dir, ec);
  auto data = preload(scenario, options.work_dir);
  if (!data) return std::unexpected(data.error());
  const std::vector<Track> tracks = tracksOf(scenario, *data, options.work_dir);

  RunResult result;
  result.scenario = scenario.name;
  result.duration_s = scenario.duration_s;
  result.sensors.resize(scenario.sensors.size());
  result.clients.resize(scenario.clients.size());
  for (std::size_t i = 0; i < scenario.sensors.size(); ++i) {
    result.sensors[i].sensor_id = scenario.sensors[i].sensor_id;
  }
  for (std::size_t i = 0; i < scenario.clients.size(); ++i) {
    result.clients[i].name = scenario.clients[i].name;
  }

  // Every participant is made and matched before the clock starts, so discovery is not
  // measured as latency. Child processes get a start time far enough out to do the same.
  auto observer = connect(options.client);
  if (!observer) return std::unexpected(observer.error());
  std::vector<std::unique_ptr<Client>> senders, queriers;
  for (const SensorPlan& p : scenario.sensors) {
    auto c = connect(options.client);
    if (!c) return makeError("sensor " + p.sensor_id + ": " + c.error().message);
    senders.push_back(std::move(*c));
  }
  Children children;
  const auto run_dir = options.work_dir / ("run-" + std::to_string(getpid()));
  Clock::time_point epoch;
  if (options.processes) {
    std::filesystem::create_directories(run_dir, ec);
    writeTracks(run_dir / "tracks.txt", tracks);
    epoch = Clock::now() + std::chrono::seconds(3) +
            std::chrono::milliseconds(100) * scenario.clients.size();
    if (auto ok = children.spawn(options, scenario, epoch, run_dir / "tracks.txt", run_dir); !ok) {
      return std::unexpected(ok.error());
    }
  } else {
    for (const ClientPlan& p : scenario.clients) {
      auto c = connect(options.client);
      if (!c) return makeError("query client " + p.name + ": " + c.error().message);
      queriers.push_back(std::move(*c));
    }
    epoch = Clock::now() + std::chrono::milliseconds(200);
  }
  auto before = (*observer)->status();
  if (!before) return std::unexpected(before.error());
  result.before = *before;
  const auto& first_status = *before;

  std::atomic<bool> stop{false};
  InFlight in_flight;
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < senders.size(); ++i) {
    const SensorPlan& p = scenario.sensors[i];
    const Dataset& d = *data->at(datasetKey(p, options.work_dir));
    threads.emplace_back([&, i, &d = d] {
      runSensor(*senders[i], scenario.sensors[i], i, d, epoch, scenario.duration_s, in_flight, stop,
                result.sensors[i]);
    });
  }
  for (std::size_t i = 0; i < queriers.size(); ++i) {
    const ClientPlan& p = scenario.clients[i];
    const Track none;
    threads.emplace_back([&, i, none] {
      const Track& t = p.around_sensor < tracks.size() ? tracks[p.around_sensor] : none;
      runQueries(*queriers[i], scenario.clients[i], i, t, epoch, scenario.duration_s, stop,
                 result.clients[i]);
    });
  }
  std::atomic<std::uint64_t> newest_version{first_status.map_version};
  if (!scenario.joiner_times_s.empty()) {
    threads.emplace_back([&] {
      for (const double t : scenario.joiner_times_s) {
        if (t >= scenario.duration_s || !sleepUntil(at(epoch, t), stop)) break;
        JoinerResult j;
        j.at_s = secondsSince(epoch);
        auto client = connect(options.client);
        if (client) {
          auto map = (*client)->fetchMap();
          if (map) {
            j.cells = map->first->knownCells();
            j.version = map->second;
          } else {
            j.error = map.error().message;
          }
        } else {
          j.error = client.error().message;
        }
        j.seconds = secondsSince(epoch) - j.at_s;
        j.versions_behind = newest_version.load() > j.version && j.error.empty()
                                ? newest_version.load() - j.version
                                : 0;
        result.joiners.push_back(std::move(j));
      }
    });
  }

  // The observer: map events (end-to-end latency) and a usage sample every second.
  std::unordered_map<std::string, std::size_t> sensor_index;
  for (std::size_t i = 0; i < scenario.sensors.size(); ++i) {
    sensor_index[scenario.sensors[i].sensor_id] = i;
  }
  auto sample = [&] {
    UsageSample u;
    u.t_s = secondsSince(epoch);
    if (auto s = (*observer)->status(); s) {
      u.server_cpu_s = s->cpu_s;
      u.server_rss = s->rss_bytes;
      u.known_cells = s->known_cells;
      u.map_version = s->map_version;
      u.map_bytes = s->memory_bytes;
      u.integrated = s->integrated;
      u.dropped = s->dropped;
      u.rejected = s->rejected;
      result.after = *s;
    }
    u.load_cpu_s = processUsage().cpu_s + children.cpuSeconds();
    const MachineCpu m = machineCpu();
    u.machine_busy_s = m.busy_s;
    u.machine_total_s = m.total_s;
    result.usage.push_back(u);
  };
  double last_event_s = 0;
  auto poll = [&] {
    (*observer)->pollEvents([&](const MapEventInfo& e) {
      newest_version = std::max(newest_version.load(), e.new_version);
      if (!e.from_scan) return;
      const auto it = sensor_index.find(e.sensor_id);
      if (it == sensor_index.end()) return;
      if (const auto sent = in_flight.seen(it->second, e.scan_seq)) {
        const double now = secondsSince(epoch);
        auto& s = result.sensors[it->second];
        ++s.seen;
        s.e2e.push_back({*sent, (now - *sent) * 1000.0});
        last_event_s = now;
      }
    });
  };
  sleepUntil(epoch, stop);
  sample();
  double next_sample = 1.0, next_progress = 5.0;
  while (secondsSince(epoch) < scenario.duration_s) {
    poll();
    const double now = secondsSince(epoch);
    if (now >= next_sample) {
      sample();
      next_sample += 1.0;
    }
    if (options.progress && now >= next_progress) {
      std::uint64_t sent = 0, seen = 0;
      for (const auto& s : result.sensors) sent += s.sent, seen += s.seen;
      std::fprintf(stderr, "load: %s %.0f/%.0f s, scans sent %llu, integrated and seen %llu\n",
                   scenario.name.c_str(), now, scenario.duration_s,
                   static_cast<unsigned long long>(sent), static_cast<unsigned long long>(seen));
      next_progress += 5.0;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  // Drain: senders and clients stop at the end time; late joiners are cut short.
  stop = true;
  for (auto& t : threads) t.join();
  children.collect(std::chrono::seconds(15), result.clients);
  // Until every scan sent is seen or counted dropped/rejected, or 3 s without news (at most 15).
  const double drain_start = secondsSince(epoch);
  last_event_s = std::max(last_event_s, drain_start);
  auto accounted = [&] {
    for (const auto& s : result.sensors) {
      std::uint64_t lost = 0;
      for (const SensorCounters& c : result.after.sensors) {
        if (c.sensor_id != s.sensor_id) continue;
        lost = c.dropped + c.rejected;
        for (const SensorCounters& b : first_status.sensors) {
          if (b.sensor_id == c.sensor_id) lost -= std::min(lost, b.dropped + b.rejected);
        }
      }
      if (s.seen + lost < s.sent) return false;
    }
    return true;
  };
  while (secondsSince(epoch) - last_event_s < 3.0 && secondsSince(epoch) - drain_start < 15.0) {
    poll();
    if (secondsSince(epoch) >= next_sample) {
      sample();
      next_sample += 1.0;
      if (accounted()) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // one more status period
  sample();
  // The server's counts per stream: the difference over the run.
  for (auto& s : result.sensors) {
    s.server.sensor_id = s.sensor_id;
    for (const SensorCounters& c : result.after.sensors) {
      if (c.sensor_id != s.sensor_id) continue;
      s.server = c;
      for (const SensorCounters& b : first_status.sensors) {
        if (b.sensor_id != c.sensor_id) continue;
        s.server.received -= std::min(s.server.received, b.received);
        s.server.integrated -= std::min(s.server.integrated, b.integrated);
        s.server.dropped -= std::min(s.server.dropped, b.dropped);
        s.server.rejected -= std::min(s.server.rejected, b.rejected);
        s.server.seq_gaps -= std::min(s.server.seq_gaps, b.seq_gaps);
      }
    }
  }
  std::filesystem::remove_all(run_dir, ec);
  return result;
}

}  // namespace densemap::load
