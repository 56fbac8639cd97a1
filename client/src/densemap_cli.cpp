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
#include "cli_support.hpp"
#include "load_command.hpp"
#include "replay_command.hpp"

namespace densemap::cli {
namespace {

using Clock = std::chrono::steady_clock;

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
    for (const RosCloudTopicStatus& c : s.ros_clouds) {
      std::printf("  ros2 cloud topic %s: %u writer%s matched", c.topic.c_str(),
                  c.matched_writers, c.matched_writers == 1 ? "" : "s");
      if (c.incompatible_qos > 0) {
        std::printf(", %llu refused for incompatible QoS (last: %s%s)",
                    static_cast<unsigned long long>(c.incompatible_qos),
                    c.last_incompatible_policy.c_str(),
                    c.last_incompatible_policy == "reliability"
                        ? "; a best-effort publisher needs ros2.reliable_clouds: false"
                        : "");
      }
      std::printf("\n");
    }
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

/// `query point`: xyz triples, or --random N points in a cube (counts per state).
int queryPointsCommand(Client& client, std::vector<float> coords, std::uint32_t random_points,
                       float random_spread) {
  if (random_points > 0) {
    if (!coords.empty()) return fail("give xyz or --random, not both");
    std::mt19937 generator(42);
    std::uniform_real_distribution<float> axis(-random_spread, random_spread);
    coords.resize(std::size_t{random_points} * 3);
    for (float& c : coords) c = axis(generator);
    const auto t0 = std::chrono::steady_clock::now();
    auto answer = client.queryPointsRaw(coords);
    if (!answer) return fail(answer.error().message);
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
    return fail("point coordinates come in threes (or give --random N)");
  auto answer = client.queryPointsRaw(coords);
  if (!answer) return fail(answer.error().message);
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

/// `status [--watch]`.
int statusCommand(Client& client, bool watch) {
  // --watch: a line every second, flushed (a pipe or file sees it at once); a server that
  // stops (its status gone, or no new status for 5 s) ends the watch with an error.
  double last_uptime = -1;
  auto last_change = std::chrono::steady_clock::now();
  do {
    auto s = client.status();
    if (!s) return fail(s.error().message);
    if (s->uptime_s != last_uptime) {
      last_uptime = s->uptime_s;
      last_change = std::chrono::steady_clock::now();
      printStatus(*s);
      std::fflush(stdout);
    } else if (std::chrono::steady_clock::now() - last_change > std::chrono::seconds(5)) {
      return fail("no new status from the server for 5 s: it has stopped or hangs");
    }
    if (watch) std::this_thread::sleep_for(std::chrono::seconds(1));
  } while (watch);
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

  cli::ReplayCommand replay(app);

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
  if (replay.parsed()) return replay.run(o);
  auto client = cli::connect(o);
  if (!client) return cli::fail(client.error().message);
  auto p3 = [](const std::vector<float>& v) { return Point3f(v[0], v[1], v[2]); };
  if (qpoint->parsed()) {
    return cli::queryPointsCommand(**client, coords, random_points, random_spread);
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
  if (status->parsed()) return cli::statusCommand(**client, watch);
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap", [&] { return runMain(argc, argv); });
}
