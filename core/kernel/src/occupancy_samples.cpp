#include "densemap/kernel/occupancy_samples.hpp"

#include <cmath>

namespace densemap::kernel {

double uniformFromCounter(std::uint64_t counter) {
  std::uint64_t z = counter + 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * 0x1p-53;
}

std::vector<Sample> makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                                const SamplingOptions& options, std::uint64_t scan_index) {
  std::vector<Sample> samples;
  const Eigen::Vector3d origin = origin_world.cast<double>();
  const double step = options.free_step;
  std::uint64_t ray_index = 0;
  for (const Point3f& p : points_world) {
    const std::uint64_t ray_key = options.seed * 0xD1B54A32D192ED03ULL ^
                                  scan_index * 0x8CB92BA72F3D8DD7ULL ^ (ray_index++ << 20);
    const Eigen::Vector3d point = p.cast<double>();
    Eigen::Vector3d direction = point - origin;
    double length = direction.norm();
    if (!(length > 0.0)) continue;
    direction /= length;
    const bool cut = options.max_range >= 0.0 && length > options.max_range;
    if (cut) {
      length = options.max_range;
    } else {
      samples.push_back({point, point, length, true, false});
    }
    const auto intervals = static_cast<std::uint64_t>(std::floor(length / step));
    for (std::uint64_t k = 0; k < intervals; ++k) {
      const double start = static_cast<double>(k) * step;
      Sample s;
      s.occupied = false;
      switch (options.free) {
        case FreeSampling::kRandomPerInterval:
          s.range = start + uniformFromCounter(ray_key + k) * step;
          s.x = origin + s.range * direction;
          break;
        case FreeSampling::kRegular:
          s.range = start + 0.5 * step;
          s.x = origin + s.range * direction;
          break;
        case FreeSampling::kSegments:
          s.range = start;
          s.x = origin + start * direction;
          s.to = origin + (start + step) * direction;
          s.segment = true;
          break;
      }
      if (!s.segment) s.to = s.x;
      samples.push_back(s);
    }
  }
  return samples;
}

}  // namespace densemap::kernel
