// densemap: the client CLI of densemap-server (replay, query, snapshot, status, commands) and an
// offline map renderer.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <thread>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/client/client.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/io/png_writer.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/upsample/interpolation.hpp"
#include "load_command.hpp"
#include "ros_replay.hpp"

namespace densemap::cli {
namespace {

using Clock = std::chrono::steady_clock;

int fail(const std::string& message) {
  std::fprintf(stderr, "densemap: error: %s\n", message.c_str());
  return 1;
}

/// --pki DIR --role R fills the six files; an explicit file flag replaces its one. Without any
/// of them: no DDS Security.
Expected<std::optional<dds::SecurityFiles>> securityOptions(
    const std::string& pki_dir, const std::string& role, const dds::SecurityFiles& explicit_files) {
  if (!pki_dir.empty() && role.empty()) return makeError("--pki needs --role");
  if (pki_dir.empty() && !role.empty()) return makeError("--role needs --pki");
  dds::SecurityFiles files =
      pki_dir.empty() ? dds::SecurityFiles{} : dds::SecurityFiles::fromPkiDir(pki_dir, role);
  bool any = !pki_dir.empty();
  for (const dds::SecurityFileField& f : dds::kSecurityFileFields) {
    const std::string& given = explicit_files.*f.member;
    if (given.empty()) continue;
    files.*f.member = given;
    any = true;
  }
  if (!any) return std::optional<dds::SecurityFiles>();
  if (auto ok = dds::checkSecurityFiles(files); !ok) return std::unexpected(ok.error());
  return std::optional<dds::SecurityFiles>(files);
}

Expected<std::unique_ptr<Client>> connect(const ClientOptions& o) {
  auto client = Client::create(o);
  if (!client) return client;
  if (auto ok = (*client)->waitForServer(); !ok) return std::unexpected(ok.error());
  return client;
}

/// `replay --ros`: the scans go out as PointCloud2 + TF (ros_replay.hpp) instead.
struct RosReplay {
  std::string topic = "/points";
  ros2::ReplayFrames frames;
  bool reliable = true;
};

int replay(const ClientOptions& o, const std::string& data, double rate, std::size_t first,
           std::size_t limit, std::size_t query_points,
           const std::optional<upsample::UpsampleOptions>& densify, const std::string& csv_path,
           double bbox_edge_m, const std::optional<RosReplay>& ros) {
  auto source = openScanSource(data);
  if (!source) return fail(source.error().message);
  if (densify) {
    if (auto ok = densify->validate(); !ok) return fail(ok.error().message);
  }
  auto client = connect(o);
  if (!client) return fail(client.error().message);
  auto before = (*client)->status();
  std::unique_ptr<RosReplayPublisher> ros_out;
  if (ros) {
    if (before && !before->ros_enabled) {
      return fail("--ros: the server's ROS 2 face is off (config: ros2 { enabled: true })");
    }
    ros2::ReplayFrames frames = ros->frames;
    if (frames.stamp_base_ns == 0) {
      frames.stamp_base_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                 std::chrono::system_clock::now().time_since_epoch())
                                 .count();
    }
    if (rate > 0) frames.period_ns = static_cast<std::int64_t>(1e9 / rate);
    auto p = RosReplayPublisher::create({o.domain_id, o.network_interface, o.security}, ros->topic,
                                        frames, ros->reliable);
    if (!p) return fail(p.error().message);
    if (auto ok = (*p)->waitForReader(static_cast<int>(o.timeout.count())); !ok) {
      return fail(ok.error().message);
    }
    ros_out = std::move(*p);
  }
  std::optional<RawScan> last_raw;
  std::size_t dropped_points = 0;
  const std::size_t end =
      limit == 0 ? (*source)->size() : std::min((*source)->size(), first + limit);
  std::map<std::uint64_t, Clock::time_point> sent_at;
  std::vector<double> latencies;
  std::size_t queried = 0;
  double query_seconds = 0.0;
  std::vector<double> point_ms;  // round trip of each point-query batch
  // --query-bbox-edge: a second client asks for bbox queries (cubes of that edge around the
  // latest sensor position) back to back, for as long as the replay sends scans.
  std::atomic<bool> replaying{true};
  std::atomic<float> centre_x{0}, centre_y{0}, centre_z{0};
  std::vector<double> bbox_ms;
  std::size_t bbox_failed = 0;
  std::thread bbox_load;
  if (bbox_edge_m > 0) {
    bbox_load = std::thread([&] {
      auto other = connect(o);
      if (!other) {
        std::fprintf(stderr, "densemap: bbox load: %s\n", other.error().message.c_str());
        return;
      }
      while (replaying.load()) {
        const Point3f c(centre_x.load(), centre_y.load(), centre_z.load());
        const Point3f half = Point3f::Constant(static_cast<float>(bbox_edge_m / 2));
        const auto t0 = Clock::now();
        if ((*other)->queryBox(c - half, c + half)) {
          bbox_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        } else {
          ++bbox_failed;
        }
      }
    });
  }
  // --csv: a row per integrated scan, with the map's size from the latest status (1 Hz).
  std::FILE* csv = nullptr;
  if (!csv_path.empty()) {
    csv = std::fopen(csv_path.c_str(), "w");
    if (csv == nullptr) return fail("cannot write " + csv_path);
    std::fprintf(csv,
                 "scan,server_ms,end_to_end_ms,changed_cells,written_blocks,known_cells,"
                 "map_bytes\n");
  }
  ServerStatus last_status = before ? *before : ServerStatus{};
  auto next_status = Clock::now() + std::chrono::seconds(1);
  auto collect = [&] {
    if (csv != nullptr && Clock::now() >= next_status) {
      if (auto s = (*client)->status(); s) last_status = *s;
      next_status = Clock::now() + std::chrono::seconds(1);
    }
    (*client)->pollEvents([&](const MapEventInfo& d) {
      const auto it = sent_at.find(d.scan_seq);
      if (!d.from_scan || it == sent_at.end()) return;
      latencies.push_back(
          std::chrono::duration<double, std::milli>(Clock::now() - it->second).count());
      sent_at.erase(it);
      if (csv != nullptr) {
        std::fprintf(csv, "%llu,%.3f,%.3f,%llu,%u,%llu,%llu\n",
                     static_cast<unsigned long long>(d.scan_seq - 1), d.latency_ms,
                     latencies.back(), static_cast<unsigned long long>(d.changed_cells),
                     d.written_blocks, static_cast<unsigned long long>(last_status.known_cells),
                     static_cast<unsigned long long>(last_status.memory_bytes));
      }
    });
  };
  tools::Progress progress("replay: scan", end - first);
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(rate > 0 ? 1.0 / rate : 0.0));
  auto next = Clock::now();
  std::size_t sent = 0;
  for (std::size_t i = first; i < end; ++i) {
    auto scan = (*source)->load(i);
    if (!scan) return fail(scan.error().message);
    // A sensor's missing returns are dropped here, as the ROS path and the offline tools do:
    // the server refuses a whole scan with one NaN (from a broken or hostile publisher).
    dropped_points += scan->removeNonFinitePoints();
    if (densify) {
      if (scan->frame != PointFrame::kSensor) {
        return fail("--upsample needs sensor-frame scans; " + data + " stores world-frame points");
      }
      scan->points = upsample::upsamplePoints(scan->points, *densify);
      scan->intensities.clear();
    }
    // The server numbers ROS clouds per topic as they arrive (1, 2, ...): key events on that.
    const RawScan raw = toRawScan(*scan, ros ? sent + 1 : i + 1, "replay");
    // Wait for the publish slot while watching events, so latencies are not quantised by it.
    while (Clock::now() < next) {
      collect();
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    next += period;
    sent_at[raw.seq] = Clock::now();
    if (auto ok = ros_out ? ros_out->publish(raw, sent) : (*client)->publishScan(raw); !ok) {
      return fail(ok.error().message);
    }
    if (ros_out) last_raw = raw;
    ++sent;
    {
      const Point3f c = scan->originWorld();
      centre_x = c.x(), centre_y = c.y(), centre_z = c.z();
    }
    if (query_points > 0) {  // query load while ingesting: points around the sensor
      std::vector<Point3f> probe;
      const Point3f c = scan->originWorld();
      for (std::size_t k = 0; k < query_points; ++k) {
        const float a = 0.618034F * static_cast<float>(k),
                    r = 20.0F * static_cast<float>(k % 97) / 97.0F;
        probe.emplace_back(c.x() + r * std::cos(a), c.y() + r * std::sin(a),
                           c.z() - 1.0F + static_cast<float>(k % 7) * 0.4F);
      }
      const auto t0 = Clock::now();
      if (auto answer = (*client)->queryPoints(probe); answer) {
        query_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
        point_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
        queried += probe.size();
      }
    }
    collect();
    progress.update(i - first + 1, std::to_string(latencies.size()) + " integrated");
  }
  // A cloud stamped after its pose's TF sample needs the next one.
  if (ros_out && last_raw) {
    if (auto ok = ros_out->finish(*last_raw, sent); !ok) return fail(ok.error().message);
  }
  // Wait for the last events: until every scan is seen or nothing new for 3 s.
  auto last_news = Clock::now();
  while (!sent_at.empty() && Clock::now() - last_news < std::chrono::seconds(3)) {
    const std::size_t had = latencies.size();
    collect();
    if (latencies.size() != had) last_news = Clock::now();
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  replaying = false;
  if (bbox_load.joinable()) bbox_load.join();
  if (csv != nullptr) std::fclose(csv);
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // one more status period
  auto after = (*client)->status();
  std::printf("replay: sent %zu scans from %s\n", sent, (*source)->describe().c_str());
  if (dropped_points > 0) {
    std::printf("replay: dropped %zu NaN/Inf points before sending\n", dropped_points);
  }
  if (before && after) {
    std::printf("replay: server integrated %llu, dropped %llu, rejected %llu (last reason: %s)\n",
                static_cast<unsigned long long>(after->integrated - before->integrated),
                static_cast<unsigned long long>(after->dropped - before->dropped),
                static_cast<unsigned long long>(after->rejected - before->rejected),
                after->last_reject_reason.empty() ? "-" : after->last_reject_reason.c_str());
    std::printf("replay: server-side latency (receive -> published) p50 %.1f ms, p99 %.1f ms\n",
                after->latency_p50_ms, after->latency_p99_ms);
  }
  std::printf(
      "replay: end-to-end latency (publish -> map event seen) over %zu scans: p50 %.1f ms, p99 "
      "%.1f "
      "ms\n",
      latencies.size(), percentile(latencies, 0.5), percentile(latencies, 0.99));
  if (queried > 0) {
    std::printf(
        "replay: point queries while ingesting: %zu points in %.3f s of requests, %.3g points/s "
        "(round trip)\n",
        queried, query_seconds, static_cast<double>(queried) / query_seconds);
    std::printf(
        "replay: point-query round trip over %zu batches of %zu: p50 %.1f ms, p99 %.1f ms\n",
        point_ms.size(), query_points, percentile(point_ms, 0.5), percentile(point_ms, 0.99));
  }
  if (bbox_edge_m > 0) {
    std::printf(
        "replay: bbox queries (%.1f m cubes) alongside: %zu answered, %zu failed, round trip "
        "p50 %.1f ms, p99 %.1f ms\n",
        bbox_edge_m, bbox_ms.size(), bbox_failed, percentile(bbox_ms, 0.5),
        percentile(bbox_ms, 0.99));
  }
  // A replay none of whose scans reached the map failed, whatever the reason.
  if (sent > 0 && before && after && after->integrated == before->integrated) {
    return fail("no scan of " + std::to_string(sent) + " was integrated (rejected " +
                std::to_string(after->rejected - before->rejected) + ", last reason: " +
                (after->last_reject_reason.empty() ? "-" : after->last_reject_reason) + ")");
  }
  return 0;
}

void printStatus(const ServerStatus& s) {
  std::printf(
      "map version %llu, %llu known cells, %.1f MiB; received %llu, integrated %llu, "
      "dropped %llu, rejected %llu%s%s; latency p50 %.1f ms p99 %.1f ms; queries %llu "
      "(%llu rejected); up %.0f s\n",
      static_cast<unsigned long long>(s.map_version),
      static_cast<unsigned long long>(s.known_cells), s.memory_bytes / 1048576.0,
      static_cast<unsigned long long>(s.received), static_cast<unsigned long long>(s.integrated),
      static_cast<unsigned long long>(s.dropped), static_cast<unsigned long long>(s.rejected),
      s.last_reject_reason.empty() ? "" : ", last: ", s.last_reject_reason.c_str(),
      s.latency_p50_ms, s.latency_p99_ms, static_cast<unsigned long long>(s.queries_answered),
      static_cast<unsigned long long>(s.queries_rejected), s.uptime_s);
  for (const SensorCounters& c : s.sensors) {
    std::printf(
        "  sensor %s: received %llu, integrated %llu, dropped %llu, rejected %llu, seq gaps %llu\n",
        c.sensor_id.c_str(), static_cast<unsigned long long>(c.received),
        static_cast<unsigned long long>(c.integrated), static_cast<unsigned long long>(c.dropped),
        static_cast<unsigned long long>(c.rejected), static_cast<unsigned long long>(c.seq_gaps));
  }
  std::printf("  memory: process RSS %.1f MiB", s.rss_bytes / 1048576.0);
  if (s.evicted_blocks > 0) {
    std::printf("; evicted %llu blocks (%llu cells) outside map.keep_radius_m / map.bounds",
                static_cast<unsigned long long>(s.evicted_blocks),
                static_cast<unsigned long long>(s.evicted_cells));
  }
  std::printf("\n");
  if (!s.last_query_error.empty()) {
    std::printf("  last refused request: %s\n", s.last_query_error.c_str());
  }
  if (s.snapshot_failures > 0) {
    std::printf("  SNAPSHOTS FAILING: %llu failed saves, last: %s\n",
                static_cast<unsigned long long>(s.snapshot_failures),
                s.last_snapshot_error.c_str());
  }
  if (s.ros_enabled) {
    std::printf(
        "  ros2: clouds received %llu, submitted %llu, malformed %llu%s%s, no transform %llu; "
        "map topics published %llu times\n",
        static_cast<unsigned long long>(s.ros_received),
        static_cast<unsigned long long>(s.ros_submitted),
        static_cast<unsigned long long>(s.ros_rejected),
        s.ros_last_reject.empty() ? "" : ", last: ", s.ros_last_reject.c_str(),
        static_cast<unsigned long long>(s.ros_no_transform),
        static_cast<unsigned long long>(s.ros_maps_published));
  }
}

Expected<std::unique_ptr<OccupancyMap>> loadMapFile(const std::string& file) {
  const std::filesystem::path p(file);
  if (p.extension() == ".bt" || p.extension() == ".ot") return importOctomap(p, Backend::kGrid);
  auto loaded = loadSnapshot(p, Backend::kGrid, 0.0);
  if (!loaded) return std::unexpected(loaded.error());
  return std::move(loaded->map);
}

int render(const std::string& in, const std::string& out, std::optional<double> z_m, int scale,
           int min_occupied) {
  auto map = loadMapFile(in);
  if (!map) return fail(map.error().message);
  if ((*map)->knownCells() == 0) return fail(in + ": the map is empty");
  int x0 = 65535, y0 = 65535, x1 = 0, y1 = 0;
  (*map)->forEachKnown([&](const VoxelKey& k, float) {
    x0 = std::min<int>(x0, k.x), y0 = std::min<int>(y0, k.y);
    x1 = std::max<int>(x1, k.x), y1 = std::max<int>(y1, k.y);
  });
  const int w = x1 - x0 + 1, h = y1 - y0 + 1;
  if (static_cast<long long>(w) * h * scale * scale > 64LL * 1024 * 1024) {
    return fail("the picture would exceed 64 megapixels; use a coarser map or --scale 1");
  }
  const std::optional<std::uint16_t> z_key = z_m ? (*map)->grid().coordToKey(*z_m) : std::nullopt;
  if (z_m && !z_key) return fail("--z is outside the map");
  // Per column: occupied-cell count and whether anything is known. In a top view a column is
  // occupied when it holds at least `min_occupied` occupied cells, so one-cell-thick ground
  // does not hide the structures standing on it.
  std::vector<int> occupied(static_cast<std::size_t>(w) * h, 0);
  std::vector<std::uint8_t> state(static_cast<std::size_t>(w) * h, 0);  // 0 unknown 1 free 2 occ
  const int needed = z_key ? 1 : min_occupied;
  (*map)->forEachKnown([&](const VoxelKey& k, float v) {
    if (z_key && k.z != *z_key) return;
    const std::size_t i = static_cast<std::size_t>(y1 - k.y) * w + (k.x - x0);
    if (SensorModel::isOccupied(v) && ++occupied[i] >= needed) state[i] = 2;
    state[i] = std::max<std::uint8_t>(state[i], 1);
  });
  const int W = w * scale, H = h * scale;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(W) * H * 3);
  const std::uint8_t colours[3][3] = {{128, 128, 128}, {240, 240, 235}, {20, 40, 160}};
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const auto& c = colours[state[static_cast<std::size_t>(y / scale) * w + x / scale]];
      std::copy(c, c + 3, rgb.begin() + (static_cast<std::ptrdiff_t>(y) * W + x) * 3);
    }
  }
  if (auto ok = writePng(out, W, H, rgb); !ok) return fail(ok.error().message);
  std::printf("wrote %s (%dx%d, %s; occupied blue, free white, unknown grey)\n", out.c_str(), W, H,
              z_m ? "z-slice" : "top view");
  return 0;
}

}  // namespace
}  // namespace densemap::cli

static int runMain(int argc, char** argv) {
  using namespace densemap;
  CLI::App app{"densemap: client of densemap-server (DDS, loopback by default)"};
  app.require_subcommand(1);
  ClientOptions o;
  int timeout_ms = 5000;
  app.add_option("--domain-id", o.domain_id, "DDS domain id")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  auto* interface_option =
      app.add_option("--interface", o.network_interface, "Network interface for DDS")
          ->capture_default_str();
  app.add_option("--timeout-ms", timeout_ms, "Request timeout")
      ->check(CLI::Range(1, 3'600'000))
      ->capture_default_str();
  std::string pki_dir, pki_role;
  dds::SecurityFiles security;
  app.add_option("--pki", pki_dir,
                 "DDS Security: a directory made by scripts/make-pki.sh (with --role)")
      ->group("DDS Security");
  app.add_option("--role", pki_role, "DDS Security: the identity in --pki to use")
      ->check(CLI::IsMember({"robot", "operator", "viewer", "server"}))
      ->group("DDS Security");
  for (const dds::SecurityFileField& f : dds::kSecurityFileFields) {
    app.add_option(dds::securityFlag(f), security.*f.member,
                   "DDS Security file (overrides the one from --pki)")
        ->group("DDS Security");
  }

  auto* replay = app.add_subcommand("replay", "Publish a dataset's scans to the server");
  std::string data;
  double rate = 10.0;
  std::size_t first = 0, limit = 0;
  replay->add_option("--data", data, "Dataset (any format densemap reads)")->required();
  replay->add_option("--rate", rate, "Scans per second (0: as fast as possible)")
      ->capture_default_str();
  replay->add_option("--first", first, "Skip this many scans")->capture_default_str();
  std::string replay_csv;
  double bbox_edge = 0;
  replay
      ->add_option("--query-bbox-edge", bbox_edge,
                   "While replaying, a second client sends bbox queries back to back: cubes of "
                   "this edge (m) around the latest sensor position (0: none)")
      ->check(CLI::Range(0.0, 1000.0));
  replay->add_option("--csv", replay_csv,
                     "Write a row per integrated scan: scan, server and end-to-end latency (ms), "
                     "changed cells, written blocks, known cells and map bytes (latest status)");
  replay->add_option("--limit", limit, "At most this many scans (0: all)")->capture_default_str();
  std::size_t query_points = 0;
  replay
      ->add_option("--query-points", query_points,
                   "After each scan, query this many points near the sensor (load test)")
      ->capture_default_str();

  std::string upsample_method, upsample_input = "16x1024", upsample_output = "64x1024";
  double fov_top = 15.0, fov_bottom = -15.0;
  replay
      ->add_option("--upsample", upsample_method,
                   "Densify each scan before sending: bilinear, nearest or iln")
      ->check(CLI::IsMember({"bilinear", "nearest", "iln"}));
  std::string upsample_model = "models/iln.pb";
  replay->add_option("--upsample-model", upsample_model, "ILN weights file (--upsample iln)")
      ->capture_default_str();
  replay->add_option("--upsample-input", upsample_input, "The sensor's grid ROWSxCOLS")
      ->capture_default_str();
  replay->add_option("--upsample-output", upsample_output, "The grid sent, ROWSxCOLS")
      ->capture_default_str();
  replay->add_option("--fov-top", fov_top, "The sensor's top beam, deg")->capture_default_str();
  replay->add_option("--fov-bottom", fov_bottom, "Its bottom beam, deg")->capture_default_str();
  bool replay_ros = false;
  cli::RosReplay ros_replay;
  replay->add_flag("--ros", replay_ros,
                   "Publish as a ROS 2 robot: sensor_msgs/PointCloud2 on --ros-topic and TF "
                   "(map -> odom static, odom -> base_link per scan, base_link -> lidar static) "
                   "on rt/tf and rt/tf_static; the server needs ros2 { enabled: true }");
  replay->add_option("--ros-topic", ros_replay.topic, "ROS topic of the clouds")
      ->capture_default_str();
  replay
      ->add_option("--ros-stamp-offset", ros_replay.frames.stamp_offset,
                   "Stamp each cloud this fraction of a scan period after its pose's TF sample "
                   "(0.5: the server interpolates between two samples and waits for the next)")
      ->check(CLI::Range(0.0, 0.99))
      ->capture_default_str();
  replay
      ->add_option("--ros-stamp-base-ns", ros_replay.frames.stamp_base_ns,
                   "Stamp of the first scan, ns (0: now); the next are 1/rate apart")
      ->capture_default_str();
  replay
      ->add_flag("!--ros-best-effort", ros_replay.reliable,
                 "Publish clouds best effort, as LiDAR drivers do (default: reliable)")
      ->default_str("");  // a negated flag: CLI11 would print its bool as {false}

  auto* query = app.add_subcommand("query", "Query the map");
  query->require_subcommand(1);
  auto* qpoint = query->add_subcommand("point", "Occupancy at points");
  std::vector<float> coords;
  qpoint->add_option("xyz", coords, "x y z [x y z ...]");
  std::uint32_t random_points = 0;
  float random_spread = 20.0F;
  qpoint
      ->add_option("--random", random_points,
                   "Instead of xyz: N points drawn uniformly (fixed seed) within --spread of the "
                   "origin on each axis, in one request; prints the counts per state (load and "
                   "request-budget tests)")
      ->check(CLI::Range(1U, 50'000'000U));
  qpoint->add_option("--spread", random_spread, "Half-size of --random's cube, m")
      ->check(CLI::Range(0.0F, 10000.0F))
      ->capture_default_str();
  auto* qbox = query->add_subcommand("bbox", "Cell counts in a box");
  std::vector<float> bmin, bmax;
  std::uint32_t centers = 0;
  qbox->add_option("--min", bmin, "x y z")->required()->expected(3);
  qbox->add_option("--max", bmax, "x y z")->required()->expected(3);
  qbox->add_option("--centers", centers, "Return up to this many occupied cell centres");
  auto* qray = query->add_subcommand("ray", "First occupied cell along a ray");
  std::vector<float> origin, direction;
  float range = 30.0F;
  qray->add_option("--origin", origin, "x y z")->required()->expected(3);
  qray->add_option("--direction", direction, "x y z")->required()->expected(3);
  qray->add_option("--range", range, "Max range, m")->capture_default_str();

  auto* snapshot =
      app.add_subcommand("snapshot", "Fetch the map (from tiles) and write it locally");
  std::string snapshot_out;
  snapshot->add_option("--out", snapshot_out, "map.dmap, map.bt or map.ot")->required();
  auto* save = app.add_subcommand("save", "Ask the server to save a snapshot on its machine");
  std::string save_path;
  save->add_option("--path", save_path,
                   "A file name (NAME.dmap, .bt or .ot, no directories) written into the "
                   "server's snapshot.export_dir (default: its snapshot with generations)");
  auto* status = app.add_subcommand("status", "Server status");
  bool watch = false;
  status->add_flag("--watch", watch, "Print every second until interrupted");
  auto* reset = app.add_subcommand("reset", "Clear the whole map");
  auto* clear = app.add_subcommand("clear-bbox", "Forget the cells in a box");
  clear->add_option("--min", bmin, "x y z")->required()->expected(3);
  clear->add_option("--max", bmax, "x y z")->required()->expected(3);
  auto* render = app.add_subcommand("render", "Picture of a map file (top view or z-slice)");
  std::string render_in, render_out;
  std::optional<double> z;
  int scale = 2;
  int min_occupied = 3;
  render->add_option("--in", render_in, ".dmap, .bt or .ot")->required();
  render->add_option("--out", render_out, "PNG file")->required();
  render->add_option("--z", z, "Height of a z-slice, m (default: top view of all heights)");
  render->add_option("--scale", scale, "Pixels per cell")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  render
      ->add_option("--min-occupied", min_occupied,
                   "Top view: occupied cells a column needs to be drawn occupied")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  cli::LoadCommand load(app);
  CLI11_PARSE(app, argc, argv);
  o.timeout = std::chrono::milliseconds(timeout_ms);
  if (auto files = cli::securityOptions(pki_dir, pki_role, security); !files) {
    return cli::fail(files.error().message);
  } else {
    o.security = *files;
  }
  if (load.parsed()) return load.run(o, interface_option->count() > 0);

  if (render->parsed()) return cli::render(render_in, render_out, z, scale, min_occupied);
  if (replay->parsed()) {
    std::optional<upsample::UpsampleOptions> densify;
    if (!upsample_method.empty()) {
      auto in = upsample::parseRangeLayout(upsample_input, fov_top, fov_bottom);
      if (!in) return cli::fail("--upsample-input: " + in.error().message);
      auto out = upsample::parseRangeLayout(upsample_output, fov_top, fov_bottom);
      if (!out) return cli::fail("--upsample-output: " + out.error().message);
      auto options = upsample::makeUpsampleOptions(upsample_method, *in, *out, upsample_model);
      if (!options) return cli::fail("--upsample: " + options.error().message);
      densify = std::move(*options);
    }
    return cli::replay(o, data, rate, first, limit, query_points, densify, replay_csv, bbox_edge,
                       replay_ros ? std::optional<cli::RosReplay>(ros_replay) : std::nullopt);
  }
  auto client = cli::connect(o);
  if (!client) return cli::fail(client.error().message);
  auto p3 = [](const std::vector<float>& v) { return Point3f(v[0], v[1], v[2]); };
  if (qpoint->parsed()) {
    if (random_points > 0) {
      if (!coords.empty()) return cli::fail("give xyz or --random, not both");
      std::mt19937 generator(42);
      std::uniform_real_distribution<float> axis(-random_spread, random_spread);
      coords.resize(std::size_t{random_points} * 3);
      for (float& c : coords) c = axis(generator);
      const auto t0 = std::chrono::steady_clock::now();
      auto answer = (*client)->queryPointsRaw(coords);
      if (!answer) return cli::fail(answer.error().message);
      std::size_t counts[3] = {0, 0, 0};
      for (const auto state : answer->states) ++counts[std::min(2, static_cast<int>(state))];
      std::printf(
          "%u points: unknown %zu, free %zu, occupied %zu (map version %llu) in %.0f ms\n",
          random_points, counts[0], counts[1], counts[2],
          static_cast<unsigned long long>(answer->map_version),
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
      return 0;
    }
    if (coords.empty() || coords.size() % 3 != 0)
      return cli::fail("point coordinates come in threes (or give --random N)");
    auto answer = (*client)->queryPointsRaw(coords);
    if (!answer) return cli::fail(answer.error().message);
    const char* names[] = {"unknown", "free", "occupied"};
    for (std::size_t i = 0; i < answer->states.size(); ++i) {
      std::printf("%g %g %g: %s", coords[3 * i], coords[3 * i + 1], coords[3 * i + 2],
                  names[static_cast<int>(answer->states[i])]);
      if (answer->log_odds[i])
        std::printf(" (log-odds %.4f, p %.3f)", *answer->log_odds[i],
                    SensorModel::probability(*answer->log_odds[i]));
      std::printf("\n");
    }
    std::printf("map version %llu\n", static_cast<unsigned long long>(answer->map_version));
    return 0;
  }
  if (qbox->parsed()) {
    auto a = (*client)->queryBox(p3(bmin), p3(bmax), centers);
    if (!a) return cli::fail(a.error().message);
    std::printf("occupied %llu, free %llu, unknown %llu (map version %llu)\n",
                static_cast<unsigned long long>(a->occupied),
                static_cast<unsigned long long>(a->free),
                static_cast<unsigned long long>(a->unknown),
                static_cast<unsigned long long>(a->map_version));
    for (const auto& c : a->occupied_centers) std::printf("  %g %g %g\n", c.x(), c.y(), c.z());
    return 0;
  }
  if (qray->parsed()) {
    auto a = (*client)->castRay(p3(origin), p3(direction), range);
    if (!a) return cli::fail(a.error().message);
    if (a->ray.hit) {
      std::printf("hit at %g %g %g, %.3f m (map version %llu)\n", a->ray.hit_center.x(),
                  a->ray.hit_center.y(), a->ray.hit_center.z(), a->ray.distance,
                  static_cast<unsigned long long>(a->map_version));
    } else {
      std::printf("no occupied cell within %g m (map version %llu)\n", range,
                  static_cast<unsigned long long>(a->map_version));
    }
    return 0;
  }
  if (snapshot->parsed()) {
    auto fetched = (*client)->fetchMap();
    if (!fetched) return cli::fail(fetched.error().message);
    const auto view = MapView::fromMap(*fetched->first, fetched->second);
    auto saved = saveSnapshot(*view, SensorModel{}, Backend::kGrid, snapshot_out);
    if (!saved) return cli::fail(saved.error().message);
    std::printf("wrote %s: %zu cells, map version %llu, %zu bytes\n", snapshot_out.c_str(),
                view->knownCells(), static_cast<unsigned long long>(fetched->second), *saved);
    return 0;
  }
  if (save->parsed() || reset->parsed() || clear->parsed()) {
    const auto kind = save->parsed()    ? CommandKind::kSave
                      : reset->parsed() ? CommandKind::kReset
                                        : CommandKind::kClearBox;
    auto r = clear->parsed() ? (*client)->command(kind, p3(bmin), p3(bmax))
                             : (*client)->command(kind, {0, 0, 0}, {0, 0, 0}, save_path);
    if (!r) return cli::fail(r.error().message);
    std::printf("%s\n", r->c_str());
    return 0;
  }
  if (status->parsed()) {
    // --watch: a line every second, flushed (a pipe or file sees it at once); a server that
    // stops (its status gone, or no new status for 5 s) ends the watch with an error.
    double last_uptime = -1;
    auto last_change = std::chrono::steady_clock::now();
    do {
      auto s = (*client)->status();
      if (!s) return cli::fail(s.error().message);
      if (s->uptime_s != last_uptime) {
        last_uptime = s->uptime_s;
        last_change = std::chrono::steady_clock::now();
        cli::printStatus(*s);
        std::fflush(stdout);
      } else if (std::chrono::steady_clock::now() - last_change > std::chrono::seconds(5)) {
        return cli::fail("no new status from the server for 5 s: it has stopped or hangs");
      }
      if (watch) std::this_thread::sleep_for(std::chrono::seconds(1));
    } while (watch);
    return 0;
  }
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap", [&] { return runMain(argc, argv); });
}
