// A dense map under densemap-server's heap (cli::heapOnHugePages, cli::serverHeap and
// cli::keepStageBuffersInHeap of KEEP_MIB; 0 leaves it out): 64 x 2048 rays at 0.1 m to the
// walls of a 40 x 30 x 6 m hall, then five more scans from points 0.3 m apart. Prints the
// minor page faults and CPU seconds of those five (stage_heap_cli.sh compares them).
// Usage: stage_heap_probe KEEP_MIB
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>

#include "densemap/cli/allocator.hpp"
#include "densemap/kernel/kernel_map.hpp"

namespace {

using densemap::Point3f;
using densemap::PointCloud;

PointCloud hallScan() {
  PointCloud scan;
  for (int row = 0; row < 64; ++row) {
    const double elevation = (-25.0 + 27.0 * row / 63.0) * std::numbers::pi / 180.0;
    for (int col = 0; col < 2048; ++col) {
      const double azimuth = 2.0 * std::numbers::pi * col / 2048.0;
      const double dx = std::cos(elevation) * std::cos(azimuth);
      const double dy = std::cos(elevation) * std::sin(azimuth);
      const double dz = std::sin(elevation);
      double t = 1e9;  // the nearest wall, floor or ceiling along the ray
      if (dx != 0.0) t = std::min(t, (dx > 0.0 ? 20.0 : -20.0) / dx);
      if (dy != 0.0) t = std::min(t, (dy > 0.0 ? 15.0 : -15.0) / dy);
      if (dz != 0.0) t = std::min(t, (dz > 0.0 ? 4.0 : -2.0) / dz);
      scan.emplace_back(static_cast<float>(t * dx), static_cast<float>(t * dy),
                        static_cast<float>(t * dz));
    }
  }
  return scan;
}

double cpuSeconds(const rusage& r) {
  return static_cast<double>(r.ru_utime.tv_sec + r.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(r.ru_utime.tv_usec + r.ru_stime.tv_usec);
}

}  // namespace

int main(int argc, char** argv) {
  char* end = nullptr;
  const long keep_mib = argc == 2 ? std::strtol(argv[1], &end, 10) : -1;
  if (argc != 2 || *end != '\0' || keep_mib < 0 || keep_mib > 1024) {
    std::fprintf(stderr, "usage: stage_heap_probe KEEP_MIB (0 .. 1024)\n");
    return 2;
  }
  (void)densemap::cli::heapOnHugePages(argv);
  densemap::cli::serverHeap();
  if (keep_mib > 0) densemap::cli::keepStageBuffersInHeap(static_cast<std::size_t>(keep_mib) << 20);
  densemap::kernel::KernelOptions options =
      densemap::kernel::KernelOptions::defaults(densemap::kernel::KernelMethod::kAkimapRays);
  options.max_range = 30.0;
  densemap::kernel::KernelMap map(0.1, options);
  const PointCloud scan = hallScan();
  map.integrate(scan, Point3f(0.0F, 0.0F, 0.0F));
  rusage before{}, after{};
  getrusage(RUSAGE_SELF, &before);
  for (int i = 1; i <= 5; ++i) {
    const Point3f origin(0.3F * static_cast<float>(i), 0.1F * static_cast<float>(i), 0.0F);
    PointCloud moved = scan;
    for (auto& p : moved) p += origin;
    map.integrate(moved, origin);
  }
  getrusage(RUSAGE_SELF, &after);
  std::printf("faults %ld cpu %.2f\n", after.ru_minflt - before.ru_minflt,
              cpuSeconds(after) - cpuSeconds(before));
  return 0;
}
