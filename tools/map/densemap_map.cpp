// densemap-map: builds an occupancy map from a dataset offline and writes it as an OctoMap
// file (.bt for octovis, .ot with full log-odds).
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <cstdio>

#include "../common/progress.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/raycast/integrator.hpp"

int main(int argc, char** argv) {
  std::string data, out, backend_name = "grid";
  double resolution = 0.1, max_range = -1.0;
  int threads = 0;
  CLI::App app{"densemap-map: integrate a dataset into an occupancy map and export it"};
  app.add_option("--data", data, "Dataset (any format densemap reads)")->required();
  app.add_option("--out", out, "Output map file: .bt or .ot")->required();
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
  auto source = densemap::openScanSource(data);
  if (!source) return fail(source.error().message);

  densemap::Integrator integrator({.max_range_m = max_range});
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  std::size_t rejected = 0;
  densemap::tools::Progress progress("densemap-map: scan", (*source)->size());
  for (std::size_t i = 0; i < (*source)->size(); ++i) {
    auto scan = (*source)->load(i);
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
