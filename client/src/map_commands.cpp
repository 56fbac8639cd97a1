#include "map_commands.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include "cli_support.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/io/png_writer.hpp"
#include "densemap/query/map_queries.hpp"
#include "densemap/store/snapshot.hpp"

namespace densemap::cli {
namespace {

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
        "  sensor %s: received %llu, integrated %llu, dropped %llu, rejected %llu, seq gaps %llu; "
        "latency p50 %.1f ms p99 %.1f ms\n",
        c.sensor_id.c_str(), static_cast<unsigned long long>(c.received),
        static_cast<unsigned long long>(c.integrated), static_cast<unsigned long long>(c.dropped),
        static_cast<unsigned long long>(c.rejected), static_cast<unsigned long long>(c.seq_gaps),
        c.latency_p50_ms, c.latency_p99_ms);
  }
  std::printf("  memory: process RSS %.1f MiB", s.rss_bytes / 1048576.0);
  if (s.evicted_blocks > 0) {
    std::printf("; evicted %llu blocks (%llu cells) outside map.keep_radius_m / map.bounds",
                static_cast<unsigned long long>(s.evicted_blocks),
                static_cast<unsigned long long>(s.evicted_cells));
  }
  if (s.decayed_cells > 0) {
    std::printf("; %llu occupied cells decayed to unknown (map.decay)",
                static_cast<unsigned long long>(s.decayed_cells));
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
  if (const HistoryStatus& h = s.history; h.enabled) {
    std::printf(
        "  history: %llu scans kept (%.1f MB); corrections %llu (%llu refused), %llu scans "
        "corrected, %llu poses matched no scan; %llu re-integrations",
        static_cast<unsigned long long>(h.scans), h.bytes / 1e6,
        static_cast<unsigned long long>(h.corrections),
        static_cast<unsigned long long>(h.corrections_rejected),
        static_cast<unsigned long long>(h.corrected_scans),
        static_cast<unsigned long long>(h.unmatched_poses),
        static_cast<unsigned long long>(h.reintegrations));
    if (h.reintegrations > 0) {
      std::printf(" (last %.2f ms a scan, in version %llu)", h.last_ms_per_scan,
                  static_cast<unsigned long long>(h.last_version));
    }
    if (h.reintegrating) {
      std::printf("; RE-INTEGRATING: %llu of %llu scans",
                  static_cast<unsigned long long>(h.reintegration_done),
                  static_cast<unsigned long long>(h.reintegration_total));
    }
    std::printf("\n");
    if (!h.last_error.empty()) std::printf("  history, last error: %s\n", h.last_error.c_str());
  }
  if (s.foxglove_enabled) {
    std::printf(
        "  foxglove: %llu clients; %llu frames dropped for full send queues, %llu clients closed "
        "for stalled queues, %llu connections or operations refused\n",
        static_cast<unsigned long long>(s.foxglove_clients),
        static_cast<unsigned long long>(s.foxglove_dropped_frames),
        static_cast<unsigned long long>(s.foxglove_closed_clients),
        static_cast<unsigned long long>(s.foxglove_rejected));
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
      std::printf("  ros2 cloud topic %s: %u writer%s matched", c.topic.c_str(), c.matched_writers,
                  c.matched_writers == 1 ? "" : "s");
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

Point3f point3(const std::vector<float>& v) { return {v[0], v[1], v[2]}; }

}  // namespace

MapCommands::MapCommands(CLI::App& app) {
  snapshot_ = app.add_subcommand("snapshot", "Fetch the map (from tiles) and write it locally");
  snapshot_->add_option("--out", snapshot_out_, "map.dmap, map.bt or map.ot")->required();
  save_ = app.add_subcommand("save", "Ask the server to save a snapshot on its machine");
  save_->add_option("--path", save_path_,
                    "A file name (NAME.dmap, .bt or .ot, no directories) written into the "
                    "server's snapshot.export_dir (default: its snapshot with generations)");
  status_ = app.add_subcommand("status", "Server status");
  status_->add_flag("--watch", watch_, "Print every second until interrupted");
  reset_ = app.add_subcommand("reset", "Clear the whole map");
  clear_ = app.add_subcommand("clear-bbox", "Forget the cells in a box");
  clear_->add_option("--min", clear_min_, "x y z")->required()->expected(3);
  clear_->add_option("--max", clear_max_, "x y z")->required()->expected(3);
}

bool MapCommands::parsed() const {
  return snapshot_->parsed() || save_->parsed() || status_->parsed() || reset_->parsed() ||
         clear_->parsed();
}

Expected<void> MapCommands::check() const {
  if (clear_->parsed()) return checkBox(point3(clear_min_), point3(clear_max_));
  return {};
}

int MapCommands::run(Client& client) {
  if (snapshot_->parsed()) {
    auto fetched = client.fetchMap();
    if (!fetched) return fail(fetched.error().message);
    auto saved = fetched->save(snapshot_out_);
    if (!saved) return fail(saved.error().message);
    std::printf("wrote %s: %zu cells, map version %llu, %zu bytes\n", snapshot_out_.c_str(),
                fetched->knownCells(), static_cast<unsigned long long>(fetched->version()), *saved);
    return 0;
  }
  if (status_->parsed()) return statusCommand(client, watch_);
  auto r = save_->parsed()    ? client.save(save_path_)
           : reset_->parsed() ? client.reset()
                              : client.clearBox(point3(clear_min_), point3(clear_max_));
  if (!r) return fail(r.error().message);
  std::printf("%s\n", r->c_str());
  return 0;
}

RenderCommand::RenderCommand(CLI::App& app) {
  command_ = app.add_subcommand("render", "Picture of a map file (top view or z-slice)");
  command_->add_option("--in", in_, ".dmap, .bt or .ot")->required();
  command_->add_option("--out", out_, "PNG file")->required();
  command_->add_option("--z", z_, "Height of a z-slice, m (default: top view of all heights)");
  command_->add_option("--scale", scale_, "Pixels per cell")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  command_
      ->add_option("--min-occupied", min_occupied_,
                   "Top view: occupied cells a column needs to be drawn occupied")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
}

int RenderCommand::run() const { return render(in_, out_, z_, scale_, min_occupied_); }

}  // namespace densemap::cli
