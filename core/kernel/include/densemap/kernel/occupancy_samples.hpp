#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"

namespace densemap::kernel {

/// One occupancy observation for kernel inference: a point `x` with label occupied/free, or
/// for segment kernels (BGKOctoMap-L) a free segment from `x` to `to`. `range` is the
/// distance of `x` from the sensor.
struct Sample {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  Eigen::Vector3d to = Eigen::Vector3d::Zero();  // segment end (kSegments free samples only)
  double range = 0.0;
  bool occupied = false;
  bool segment = false;
};

enum class FreeSampling {
  kRandomPerInterval,  // AKIMap: one point drawn uniformly in each interval of `free_step`
  kRegular,            // BGKOctoMap: one point at the middle of each interval
  kSegments,           // BGKOctoMap-L: each interval is a free segment
};

struct SamplingOptions {
  FreeSampling free = FreeSampling::kRandomPerInterval;
  double free_step = 0.5;   // m between free samples (segment length for kSegments)
  double max_range = -1.0;  // < 0: unlimited; longer rays are cut and end free
  std::uint64_t seed = 1;
};

/// The samples of one scan: every point within max range is occupied; free samples lie on
/// each ray from the origin to its (cut) end. Random draws depend only on (seed, scan, ray,
/// interval), never on threads or order. Points must be finite (callers validate scans).
[[nodiscard]] std::vector<Sample> makeSamples(const PointCloud& points_world,
                                              const Point3f& origin_world,
                                              const SamplingOptions& options,
                                              std::uint64_t scan_index);

/// A uniform double in [0, 1) from a counter (SplitMix64): reproducible random numbers.
[[nodiscard]] double uniformFromCounter(std::uint64_t counter);

}  // namespace densemap::kernel
