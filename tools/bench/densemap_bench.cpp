// densemap-bench: offline integration benchmark (no DDS). Every method integrates the same
// scans in one run, the methods taking turns a few scans at a time; speed is reported as ratios
// against OctoMap's insertPointCloud, and every map is compared with OctoMap's cell by cell.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <thread>

#include "bench_report.hpp"
#include "cache_probe.hpp"
#include "cpu_steal.hpp"
#include "densemap/cli/allocator.hpp"
#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/ros2/recording.hpp"
#include "densemap/traversal/update_rule.hpp"
#include "lane.hpp"
#include "planner_timing.hpp"

namespace densemap::bench {
namespace {

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
  auto source = ros2::openAnyScanSource(o.data);
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

/// The methods, rule and backends make sense, or a message and exit status 2.
int checkOptions(const Options& o, std::vector<Backend>& backends) {
  // Settings first: a bad --kernel-set would otherwise read as an unknown dense method.
  if (kernel::KernelOptions probe; !kernel::applySettings(probe, o.kernel_settings)) {
    std::fprintf(stderr, "densemap-bench: --kernel-set: %s\n",
                 kernel::applySettings(probe, o.kernel_settings).error().message.c_str());
    return 2;
  }
  for (const auto& name : o.methods) {
    const std::string m = laneMethod(name, o.threads).method;
    if (m == "octomap" && name != m) {  // its lane would be a grid map's, OctoMap's insert on it
      std::fprintf(stderr, "densemap-bench: '%s': OctoMap runs on one thread (no @tN)\n",
                   name.c_str());
      return 2;
    }
    if (makeIntegrator(m, o)) continue;
    const auto dense = kernelOptions(m, o);
    if (!dense && m.find("@set=") != std::string::npos) {  // a known kind, a bad setting
      std::fprintf(stderr, "densemap-bench: %s\n", dense.error().message.c_str());
      return 2;
    }
    if (!dense) {
      std::fprintf(stderr,
                   "densemap-bench: unknown method '%s' or rule '%s' (methods: octomap, raycast, "
                   "superray, culling, superray+culling, and the dense kinds akimap_rays, "
                   "akimap_rays@plain, akimap, bgk, bgkl; rules: set, per_ray)\n",
                   name.c_str(), o.rule.c_str());
      return 2;
    }
  }
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
  return 0;
}

/// A lane per (method, backend), references first: under "set" OctoMap is the reference every
/// map is compared with; under "per_ray" (which OctoMap does not implement) the plain raycast
/// map is, per backend.
std::vector<std::unique_ptr<Lane>> makeLanes(const Options& o,
                                             const std::vector<Backend>& backends) {
  std::vector<std::string> order = o.methods;
  if (o.rule != "set" && std::find(order.begin(), order.end(), "raycast") == order.end()) {
    order.push_back("raycast");
  }
  std::stable_partition(order.begin(), order.end(), [](const auto& m) { return m == "raycast"; });
  std::stable_partition(order.begin(), order.end(), [](const auto& m) { return m == "octomap"; });
  std::vector<std::unique_ptr<Lane>> lanes;
  for (const auto& method : order) {
    // OctoMap's octree, a kernel map: once
    if (method == "octomap" || kernelOptions(laneMethod(method, o.threads).method, o)) {
      lanes.push_back(std::make_unique<Lane>(method, Backend::kOctree, o));
      continue;
    }
    for (const Backend backend : backends)
      lanes.push_back(std::make_unique<Lane>(method, backend, o));
  }
  return lanes;
}

/// Lanes take turns, `turn` scans at a time (0: all of them). The first lane (OctoMap's, or the
/// reference) opens every turn and the others rotate after it, so that none always follows
/// OctoMap's long serial run (caches evicted, idle workers). (Rotating all the lanes kept the
/// same lane after OctoMap's in every turn: `raycast`, whose apply stage paid for it.)
/// Returns each lane's CPU steal over its turns (by lane index).
std::vector<StealMeter> runLanes(std::vector<std::unique_ptr<Lane>>& lanes,
                                 const std::vector<WorldScan>& scans, std::size_t turn) {
  std::vector<StealMeter> steal(lanes.size());
  if (turn == 0) turn = scans.size();
  tools::Progress progress("integrating (method, scan) pair", scans.size() * lanes.size());
  std::size_t done = 0;
  for (std::size_t first = 0, t = 0; first < scans.size(); first += turn, ++t) {
    const std::size_t last = std::min(scans.size(), first + turn);
    for (std::size_t k = 0; k < lanes.size(); ++k) {
      const std::size_t index = k == 0 ? 0 : 1 + (t + k - 1) % (lanes.size() - 1);
      auto& lane = lanes[index];
      const std::optional<CpuTimes> before = readCpuTimes();
      for (std::size_t i = first; i < last; ++i) {
        char detail[96];
        std::snprintf(detail, sizeof(detail), "(%s, scan %zu: %.1f ms)", lane->name().c_str(),
                      i + 1, lane->step(scans[i], i == first));
        progress.update(++done, detail);
      }
      steal[index].add(before, readCpuTimes());
    }
  }
  return steal;
}

/// Each lane's result, its map compared cell by cell with its reference's (the reference lanes
/// come first) and its speed with OctoMap's.
std::vector<RunResult> compareLanes(std::vector<std::unique_ptr<Lane>>& lanes,
                                    const std::vector<StealMeter>& steal, bool per_ray) {
  const std::string reference_method = per_ray ? "raycast" : "octomap";
  std::vector<RunResult> runs;
  std::map<std::string, const OccupancyMap*> references;  // by backend
  double octomap_p50 = 0;
  for (std::size_t index = 0; index < lanes.size(); ++index) {
    auto& lane = lanes[index];
    RunResult r = lane->finish();
    r.cpu_steal_share = steal[index].share();
    const OccupancyMap& map = lane->map();
    if (r.method == "octomap") octomap_p50 = r.percentile(0.5);
    if (r.dense) {  // a kernel map: no cell-by-cell comparison with a log-odds map
      if (octomap_p50 > 0) r.speedup_vs_octomap = octomap_p50 / std::max(1e-9, r.percentile(0.5));
      runs.push_back(std::move(r));
      continue;
    }
    if (r.method == reference_method || r.method == "octomap") {  // its own reference
      r.reference = r.method;
      r.diff_cells = 0;
      if (r.method == "octomap") r.diff_cells_vs_octomap = 0;
      if (r.method == reference_method) references[per_ray ? r.backend : std::string()] = &map;
    } else if (const auto ref = references.find(per_ray ? r.backend : std::string());
               ref != references.end()) {
      const MapDiff diff = diffMaps(map, *ref->second);
      r.reference = reference_method;
      r.diff_cells = static_cast<long long>(diff.differing());
      if (!per_ray) r.diff_cells_vs_octomap = r.diff_cells;
      if (diff.differing() > 0) {
        std::fprintf(stderr,
                     "%s/%s differs from %s: %zu only ours, %zu only the reference's, "
                     "%zu values (max |d| %g)\n",
                     r.method.c_str(), r.backend.c_str(), reference_method.c_str(), diff.only_in_a,
                     diff.only_in_b, diff.value_mismatch,
                     static_cast<double>(diff.max_abs_difference));
      }
    }
    if (octomap_p50 > 0) r.speedup_vs_octomap = octomap_p50 / std::max(1e-9, r.percentile(0.5));
    runs.push_back(std::move(r));
  }
  return runs;
}

/// The tables on stdout (and --json, --growth); 1 when the JSON file cannot be written.
int report(const Options& o, const std::vector<RunResult>& runs,
           const std::vector<std::unique_ptr<Lane>>& lanes,
           const std::vector<WorldScan>& scans_for_queries, const CacheProbes& probes) {
  const std::size_t scans = scans_for_queries.size();
  const std::string machine = machineDescription();
  std::printf(
      "densemap-bench: %s, resolution %g m, max range %g m, %zu scans, rule %s "
      "(diff cells vs %s); %s\n",
      o.data.c_str(), o.resolution, o.max_range, scans, o.rule.c_str(),
      o.rule != "set" ? "raycast" : "octomap", machine.c_str());
  std::printf("%s\n", formatTable(runs).c_str());
  std::printf("%s", formatRayTable(runs).c_str());
  if (const std::string field = formatFieldTable(runs); !field.empty()) {
    std::printf("\n%s", field.c_str());
  }
  // Planner queries on the first lane with a field (the server's question sizes).
  for (const auto& lane : lanes) {
    if (lane->field() == nullptr) continue;
    std::printf(
        "\n%s, %d threads: %s", lane->name().c_str(), lane->threads(),
        timePlannerQueries(*lane->fieldView(), *lane->field(), scans_for_queries, lane->threads())
            .c_str());
    break;
  }
  if (lanes.size() > 1) std::printf("\n%s\n", formatTurnTable(runs).c_str());
  for (const RunResult& r : runs) {
    std::printf("%s/%s: %zu known cells, %.1f MiB (%.1f MiB per million cells)", r.method.c_str(),
                r.backend.c_str(), r.known_cells, r.memory_bytes / 1048576.0,
                r.known_cells ? r.memory_bytes / 1048576.0 / (r.known_cells / 1e6) : 0.0);
    if (r.dense)
      std::printf(", evidence digest %016llx", static_cast<unsigned long long>(r.evidence_digest));
    if (r.cpu_steal_share >= 0) std::printf("; CPU steal %.1f%%", 100.0 * r.cpu_steal_share);
    std::printf("\n");
  }
  // Above this the times say more about the host's other guests than about the method.
  constexpr double kNoisySteal = 0.05;
  for (const RunResult& r : runs) {
    if (r.cpu_steal_share > kNoisySteal) {
      std::printf(
          "warning: %.1f%% of the CPU time was stolen by the hypervisor while %s/%s ran: its "
          "times are not comparable with a quieter run's\n",
          100.0 * r.cpu_steal_share, r.method.c_str(), r.backend.c_str());
    }
  }
  if (!probes.before.empty()) {
    std::printf("%s\n%s\n",
                formatCacheProbe("before the lanes", probes.bytes, probes.before).c_str(),
                formatCacheProbe("after the lanes", probes.bytes, probes.after).c_str());
  }
  if (o.growth > 0) {
    std::printf(
        "\nper-scan time as the map grows (--growth %zu; region: the culling region's "
        "mean ms; cells and blocks: the map after the part)\n%-28s %11s %9s %9s %10s "
        "%12s %9s\n",
        o.growth, "method/backend", "scans", "p50 ms", "p99 ms", "region ms", "known cells",
        "blocks");
    for (const auto& lane : lanes) std::printf("%s", lane->growthTable(o.growth).c_str());
  }
  if (!o.json.empty()) {
    std::ofstream out(o.json);
    out << formatJson(runs, o.data, machine, probes);
    if (!out) {
      std::fprintf(stderr, "densemap-bench: cannot write %s\n", o.json.c_str());
      return 1;
    }
  }
  return 0;
}

int run(const Options& o) {
  std::vector<Backend> backends;
  if (const int bad = checkOptions(o, backends); bad != 0) return bad;
  auto scans = loadScans(o);
  if (!scans) {
    std::fprintf(stderr, "densemap-bench: error: %s\n", scans.error().message.c_str());
    return 1;
  }
  auto lanes = makeLanes(o, backends);
  // The vCPUs' share of the last-level cache, before and after (one million steps a vCPU:
  // 20-200 ms each, eight vCPUs at most).
  constexpr std::size_t kProbeSteps = 1'000'000;
  const unsigned cpus = std::clamp(std::thread::hardware_concurrency(), 1U, 8U);
  CacheProbes probes;
  probes.bytes = o.cache_probe_mib << 20;
  if (o.cache_probe_mib > 0) probes.before = probeCaches(probes.bytes, cpus, kProbeSteps);
  const std::vector<StealMeter> steal = runLanes(lanes, *scans, o.turn);
  if (o.cache_probe_mib > 0) probes.after = probeCaches(probes.bytes, cpus, kProbeSteps);
  const std::vector<RunResult> runs = compareLanes(lanes, steal, o.rule != "set");
  return report(o, runs, lanes, *scans, probes);
}

}  // namespace
}  // namespace densemap::bench

static int runMain(int argc, char** argv) {
  // As densemap-server does: the heap on huge pages (it may start the bench again for that),
  // and per-scan buffers stay in the heap for reuse (as in the Python module too).
  const densemap::cli::HeapPages heap_pages = densemap::cli::heapOnHugePages(argv);
  densemap::cli::keepScanBuffersInHeap(std::size_t{256} << 20);
  densemap::bench::Options o;
  CLI::App app{"densemap-bench: integration speed and exactness against OctoMap, one run"};
  app.add_option("--data", o.data,
                 "Dataset (directory, .graph, .pcd dir, scan.dat[.bz2], ROS 2 .mcap bag)")
      ->required();
  app.add_option("--resolution", o.resolution, "Voxel size, m")->capture_default_str();
  app.add_option("--max-range", o.max_range, "Rays are cut at this range, m (< 0: unlimited)")
      ->capture_default_str();
  app.add_option("--methods", o.methods,
                 "Comma-separated: octomap, raycast, superray, culling, superray+culling; dense "
                 "(kernel) maps: akimap_rays, akimap_rays@plain (its plain path), akimap, "
                 "bgk, bgkl; KIND@set=NAME=VALUE[:NAME=VALUE...]: a dense kind with these "
                 "settings on its lane only (a setting against the default in one run)")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--rule", o.rule,
                 "Update rule: set (OctoMap's; maps are compared with OctoMap) or per_ray "
                 "(compared with the raycast map)")
      ->check(CLI::IsMember({"set", "per_ray"}))
      ->capture_default_str();
  app.add_option("--superray-min-points", o.min_points,
                 "End voxels with fewer points are not grouped into super rays (k)")
      ->capture_default_str();
  app.add_option(
         "--grow-strides", o.grow_strides,
         "Culling methods mark rays in levels (indices multiple of each stride in turn), "
         "the culling region growing by the scan's marks after each; a method named "
         "METHOD@nogrow does not (comma-separated; 0: none); METHOD@single walks rays one at a "
         "time (not queued and walked eight at a time); METHOD@four walks the queued walks four "
         "at a time in AVX2 lanes of doubles (the kernel near-ties are handed to), "
         "METHOD@fixed eight at a time in AVX2 lanes of fixed point (the default without AVX-512), "
         "METHOD@sixteen sixteen at a time in AVX-512 lanes of fixed point (the default with it), "
         "METHOD@scalar one at a time; "
         "any method "
         "name may end in @tN: that "
         "lane runs on N threads (e.g. raycast@t1,raycast@t2 for a scaling ratio in one run)")
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
  app.add_option("--turn", o.turn,
                 "Methods take turns this many scans at a time, so that all see the machine in "
                 "the same state (0: each method runs all scans in one go)")
      ->capture_default_str();
  app.add_option("--json", o.json, "Also write the results as JSON to this file");
  app.add_option("--kernel-set", o.kernel_settings,
                 "A dense method's setting NAME=VALUE (repeatable; densemap-eval --help lists "
                 "them), for every dense method of the run");
  app.add_option("--cache-probe-mib", o.cache_probe_mib,
                 "Before and after the lanes, time a pointer chase over this many MiB on each "
                 "vCPU (ns a step: its share of the last-level cache, which other guests of a "
                 "shared host take by the minute; 0: no probe)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  app.add_option("--esdf", o.esdf_max_distance,
                 "Also keep a distance field (this maximum distance, metres) on each log-odds "
                 "grid lane, updated after every scan from the blocks it wrote; its time is a "
                 "stage of its own, beside the integration's (0: off)")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--growth", o.growth,
                 "Also print each method's p50 / p99 in this many consecutive parts of the scans, "
                 "with the map's size after each (per-scan cost against map size; 0: no)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  std::fprintf(stderr, "densemap-bench: %s\n", densemap::cli::describe(heap_pages));
  return densemap::bench::run(o);
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-bench", [&] { return runMain(argc, argv); });
}
