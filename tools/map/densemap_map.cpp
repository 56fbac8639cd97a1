// densemap-map: builds an occupancy map from a dataset offline and writes it as an OctoMap
// file (.bt for octovis, .ot with full log-odds); can also write the scans as an OctoMap
// ScanGraph (.graph) for graph2tree and octovis. For OctoMap's own inputs (.graph, scan.dat) it
// transforms the scans exactly as graph2tree does: the two build the same tree, cell for cell.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <cstdio>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/ros2/recording.hpp"

static int runMain(int argc, char** argv) {
  std::string data, out, graph_out, bag_out, backend_name = "grid";
  std::size_t first = 0, limit = 0;
  double resolution = 0.1, max_range = -1.0;
  int threads = 0;
  CLI::App app{"densemap-map: integrate a dataset into an occupancy map and export it"};
  app.add_option("--data", data, "Dataset (any format densemap reads, a ROS 2 .mcap bag too)")
      ->required();
  app.add_option("--out", out, "Output map file: .bt or .ot");
  app.add_option("--save-graph", graph_out,
                 "Also (or only, without --out) write the scans as an OctoMap ScanGraph (.graph)");
  app.add_option("--save-bag", bag_out,
                 "Also (or only) write the scans (sensor frame) as a ROS 2 bag: .mcap (zstd "
                 "chunks) or .db3, PointCloud2 + TF as densemap replay --ros publishes them");
  app.add_option("--first", first, "First scan to use (0-based)")->capture_default_str();
  app.add_option("--limit", limit, "Number of scans to use (0: all)")->capture_default_str();
  app.add_option("--resolution", resolution, "Voxel size, m")->capture_default_str();
  app.add_option("--max-range", max_range, "Ray cut-off, m (< 0: unlimited)")
      ->capture_default_str();
  app.add_option("--backend", backend_name, "grid or octree")->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  auto fail = [](const std::string& message) {
    std::fprintf(stderr, "densemap-map: error: %s\n", message.c_str());
    return 1;
  };
  auto backend = densemap::parseBackend(backend_name);
  if (!backend) return fail(backend.error().message);
  auto map = densemap::makeMap(*backend, resolution);
  if (!map) return fail(map.error().message);
  (*map)->setRunner(densemap::tbbRunner());
  if (out.empty() && graph_out.empty() && bag_out.empty())
    return fail("nothing to write: give --out, --save-graph and/or --save-bag");
  auto source = densemap::ros2::openAnyScanSource(data);
  if (!source) return fail(source.error().message);
  const std::size_t total = (*source)->size();
  if (first >= total) {
    return fail("--first " + std::to_string(first) + " is past the " + std::to_string(total) +
                " scans of " + (*source)->describe());
  }
  const std::size_t count = limit == 0 ? total - first : std::min(limit, total - first);
  if (!graph_out.empty()) {
    densemap::tools::Progress progress("densemap-map: graph scan", count);
    auto ok = densemap::writeScanGraph(**source, first, count, graph_out,
                                       [&](std::size_t n) { progress.update(n); });
    if (!ok) return fail(ok.error().message);
    std::printf("wrote %s (%zu scans)\n", graph_out.c_str(), count);
  }
  if (!bag_out.empty()) {
    densemap::tools::Progress progress("densemap-map: bag scan", count);
    auto ok = densemap::ros2::writeRecording(**source, first, count, bag_out,
                                             densemap::ros2::McapCompression::kZstd,
                                             [&](std::size_t n) { progress.update(n); });
    if (!ok) return fail(ok.error().message);
    std::printf("wrote %s (%zu scans)\n", bag_out.c_str(), count);
  }
  if (out.empty()) return 0;

  densemap::Integrator integrator({.max_range_m = max_range});
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  std::size_t rejected = 0;
  densemap::tools::Progress progress("densemap-map: scan", count);
  for (std::size_t i = 0; i < count; ++i) {
    auto scan = (*source)->load(first + i);
    if (!scan) return fail(scan.error().message);
    densemap::PointCloud points = scan->pointsWorld();
    rejected += densemap::removeNonFinite(points);
    arena.execute([&] { integrator.integrate(**map, points, scan->originWorld()); });
    progress.update(i + 1, std::to_string((*map)->knownCells()) + " known cells");
  }
  if (rejected > 0) std::fprintf(stderr, "densemap-map: dropped %zu non-finite points\n", rejected);
  if (auto ok = densemap::exportOctomap(**map, out); !ok) return fail(ok.error().message);
  std::printf("wrote %s (%zu known cells, %.1f MiB in memory)\n", out.c_str(), (*map)->knownCells(),
              (*map)->memoryBytes() / 1048576.0);
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-map", [&] { return runMain(argc, argv); });
}
