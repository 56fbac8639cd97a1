// densemap-bench: offline integration benchmark (no DDS). Every method integrates the same
// scans in one run; speed is reported as ratios against OctoMap's insertPointCloud, and every
// map is compared with OctoMap's cell by cell.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include "../common/progress.hpp"
#include "bench_report.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/raycast/integrator.hpp"

namespace densemap::bench {
namespace {

struct WorldScan {
  PointCloud points;
  Point3f origin;
};

struct Options {
  std::string data;
  double resolution = 0.2;
  double max_range = -1.0;
  std::vector<std::string> methods{"octomap", "raycast"};
  std::vector<std::string> backends{"grid", "octree"};
  int threads = static_cast<int>(std::max(1U, std::thread::hardware_concurrency()));
  std::size_t first = 0;
  std::size_t limit = 0;
  std::string json;
};

std::string machineDescription() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  return model + ", " + std::to_string(std::thread::hardware_concurrency()) + " hardware threads";
}

Expected<std::vector<WorldScan>> loadScans(const Options& o) {
  auto source = openScanSource(o.data);
  if (!source) return std::unexpected(source.error());
  const std::size_t total = (*source)->size();
  if (o.first >= total)
    return makeError("--first " + std::to_string(o.first) + " but only " + std::to_string(total) +
                     " scans");
  const std::size_t end = o.limit == 0 ? total : std::min(total, o.first + o.limit);
  std::fprintf(stderr, "densemap-bench: %s\n", (*source)->describe().c_str());
  std::vector<WorldScan> scans;
  std::size_t rejected = 0;
  tools::Progress progress("loading scan", end - o.first);
  for (std::size_t i = o.first; i < end; ++i) {
    auto scan = (*source)->load(i);
    if (!scan) return std::unexpected(scan.error());
    WorldScan w{scan->pointsWorld(), scan->originWorld()};
    rejected += removeNonFinite(w.points);
    scans.push_back(std::move(w));
    progress.update(i - o.first + 1);
  }
  if (rejected > 0)
    std::fprintf(stderr, "densemap-bench: dropped %zu non-finite points\n", rejected);
  return scans;
}

using Integrate = std::function<ScanStats(OccupancyMap&, const WorldScan&)>;

Integrate makeIntegrator(const std::string& method, const Options& o) {
  if (method == "octomap") {
    return [range = o.max_range](OccupancyMap& map, const WorldScan& s) {
      static_cast<OctreeMap&>(map).insertWithOctomap(s.points, s.origin, range);
      return ScanStats{s.points.size(), 0, 0, 0};
    };
  }
  if (method == "raycast") {
    auto integrator = std::make_shared<Integrator>(IntegratorOptions{.method = IntegrationMethod::kRaycast, .max_range_m = o.max_range});
    return [integrator](OccupancyMap& map, const WorldScan& s) {
      return integrator->integrate(map, s.points, s.origin);
    };
  }
  return nullptr;
}

RunResult runMethod(const std::string& method, Backend backend, const Options& o,
                    const std::vector<WorldScan>& scans, std::unique_ptr<OccupancyMap>& map_out) {
  auto map = makeMap(backend, o.resolution);
  map_out = std::move(*map);
  const Integrate integrate = makeIntegrator(method, o);
  RunResult r;
  r.method = method;
  r.backend = std::string(backendName(backend));
  r.threads = method == "octomap" ? 1 : o.threads;
  r.resolution = o.resolution;
  r.max_range = o.max_range;
  r.has_counts = method != "octomap";
  tbb::task_arena arena(r.threads);
  tools::Progress progress(method + "/" + r.backend + " scan", scans.size());
  double visits = 0, changed = 0;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    ScanStats stats;
    const auto t0 = std::chrono::steady_clock::now();
    arena.execute([&] { stats = integrate(*map_out, scans[i]); });
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    r.ms_per_scan.push_back(ms);
    r.total_s += ms / 1000.0;
    r.points += scans[i].points.size();
    visits += static_cast<double>(stats.visits);
    changed += static_cast<double>(stats.changed);
    char detail[32];
    std::snprintf(detail, sizeof(detail), "%.1f ms", ms);
    progress.update(i + 1, detail);
  }
  r.scans = scans.size();
  r.visits_per_scan = visits / static_cast<double>(std::max<std::size_t>(1, r.scans));
  r.changed_cells_per_scan = changed / static_cast<double>(std::max<std::size_t>(1, r.scans));
  r.known_cells = map_out->knownCells();
  r.memory_bytes = map_out->memoryBytes();
  return r;
}

int run(const Options& o) {
  for (const auto& m : o.methods) {
    if (!makeIntegrator(m, o)) {
      std::fprintf(stderr, "densemap-bench: unknown method '%s' (octomap, raycast)\n", m.c_str());
      return 2;
    }
  }
  std::vector<Backend> backends;
  for (const auto& b : o.backends) {
    auto parsed = parseBackend(b);
    if (!parsed) {
      std::fprintf(stderr, "densemap-bench: %s\n", parsed.error().message.c_str());
      return 2;
    }
    backends.push_back(*parsed);
  }
  if (auto probe = makeMap(Backend::kGrid, o.resolution); !probe) {
    std::fprintf(stderr, "densemap-bench: %s\n", probe.error().message.c_str());
    return 2;
  }
  auto scans = loadScans(o);
  if (!scans) {
    std::fprintf(stderr, "densemap-bench: error: %s\n", scans.error().message.c_str());
    return 1;
  }

  std::vector<RunResult> runs;
  std::unique_ptr<OccupancyMap> reference;
  double reference_p50 = 0;
  // OctoMap runs first: it is the reference every other map is compared with.
  std::vector<std::string> order = o.methods;
  std::stable_partition(order.begin(), order.end(), [](const auto& m) { return m == "octomap"; });
  for (const auto& method : order) {
    for (const Backend backend : backends) {
      if (method == "octomap" && backend != Backend::kOctree) {
        if (std::find(backends.begin(), backends.end(), Backend::kOctree) != backends.end())
          continue;
      }
      const Backend used = method == "octomap" ? Backend::kOctree : backend;
      std::unique_ptr<OccupancyMap> map;
      RunResult r = runMethod(method, used, o, *scans, map);
      if (method == "octomap") {
        reference = std::move(map);
        reference_p50 = r.percentile(0.5);
        r.diff_cells_vs_octomap = 0;
        r.speedup_vs_octomap = 1.0;
      } else if (reference) {
        const MapDiff diff = diffMaps(*map, *reference);
        r.diff_cells_vs_octomap = static_cast<long long>(diff.differing());
        r.speedup_vs_octomap = reference_p50 / std::max(1e-9, r.percentile(0.5));
        if (diff.differing() > 0) {
          std::fprintf(stderr,
                       "%s/%s differs from OctoMap: %zu only ours, %zu only OctoMap's, "
                       "%zu values (max |d| %g)\n",
                       method.c_str(), r.backend.c_str(), diff.only_in_a, diff.only_in_b,
                       diff.value_mismatch, static_cast<double>(diff.max_abs_difference));
        }
      }
      runs.push_back(std::move(r));
      if (method == "octomap") break;
    }
  }
  const std::string machine = machineDescription();
  std::printf("densemap-bench: %s, resolution %g m, max range %g m, %zu scans; %s\n",
              o.data.c_str(), o.resolution, o.max_range, scans->size(), machine.c_str());
  std::printf("%s", formatTable(runs).c_str());
  for (const RunResult& r : runs) {
    std::printf("%s/%s: %zu known cells, %.1f MiB (%.1f MiB per million cells)\n", r.method.c_str(),
                r.backend.c_str(), r.known_cells, r.memory_bytes / 1048576.0,
                r.known_cells ? r.memory_bytes / 1048576.0 / (r.known_cells / 1e6) : 0.0);
  }
  if (!o.json.empty()) {
    std::ofstream out(o.json);
    out << formatJson(runs, o.data, machine);
    if (!out) {
      std::fprintf(stderr, "densemap-bench: cannot write %s\n", o.json.c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace
}  // namespace densemap::bench

int main(int argc, char** argv) {
  densemap::bench::Options o;
  CLI::App app{"densemap-bench: integration speed and exactness against OctoMap, one run"};
  app.add_option("--data", o.data, "Dataset (directory, .graph, .pcd dir, scan.dat[.bz2])")
      ->required();
  app.add_option("--resolution", o.resolution, "Voxel size, m")->capture_default_str();
  app.add_option("--max-range", o.max_range, "Rays are cut at this range, m (< 0: unlimited)")
      ->capture_default_str();
  app.add_option("--methods", o.methods, "Comma-separated: octomap, raycast")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--backend", o.backends, "Comma-separated: grid, octree")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--threads", o.threads, "Worker threads for densemap's methods")
      ->check(CLI::Range(1, 256))
      ->capture_default_str();
  app.add_option("--first", o.first, "Skip this many scans")->capture_default_str();
  app.add_option("--limit", o.limit, "Use at most this many scans (0: all)")->capture_default_str();
  app.add_option("--json", o.json, "Also write the results as JSON to this file");
  CLI11_PARSE(app, argc, argv);
  return densemap::bench::run(o);
}
