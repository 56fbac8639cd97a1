#include "streams.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <thread>

#include "densemap/sim/sequence.hpp"

namespace densemap::load::detail {
namespace {

/// Preloaded scans stay under this many bytes in all: a load generator that reads files while
/// it measures would compete with the server for the same cores.
constexpr std::size_t kPreloadBudget = std::size_t{3} << 30;

}  // namespace

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

}  // namespace densemap::load::detail
