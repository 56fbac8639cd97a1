#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <functional>
#include <span>
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
  bool tip = false;  // the thin last free segment before a hit (makeRaySegments)
};

enum class FreeSampling {
  kRandomPerInterval,  // AKIMap: one point drawn uniformly in each interval of `free_step`
  kRegular,            // BGKOctoMap: one point at the middle of each interval
  kSegments,           // BGKOctoMap-L: each interval is a free segment
  kNone,               // no free samples: the hits only
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
/// `keep_free`, when given, drops the free samples it returns false for (the random draws of
/// the others do not change).
[[nodiscard]] std::vector<Sample> makeSamples(
    const PointCloud& points_world, const Point3f& origin_world, const SamplingOptions& options,
    std::uint64_t scan_index,
    const std::function<bool(const Eigen::Vector3d&)>& keep_free = nullptr);
/// The same into `out` (cleared; its capacity is kept, so a caller's buffer serves every scan).
void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index,
                 const std::function<bool(const Eigen::Vector3d&)>& keep_free,
                 std::vector<Sample>& out);
/// The same with the per-chunk buffers of the parallel draw kept by the caller too.
void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index,
                 const std::function<bool(const Eigen::Vector3d&)>& keep_free,
                 std::vector<Sample>& out, std::vector<std::vector<Sample>>& parts);

/// Whether a point lies within `reach` (per axis, a box) of a scan's hits, by a bitmap of
/// cubes of `reach` over the hits' bounding box: a superset (it may say yes a little farther
/// away, never no within reach). For kAkimapRays, whose free samples only shape occupied
/// kernels through the search boxes around hits.
class NearHits {
 public:
  NearHits(const std::vector<Eigen::Vector3d>& hits, double reach);
  [[nodiscard]] bool operator()(const Eigen::Vector3d& x) const {
    std::int64_t c[3];
    for (int a = 0; a < 3; ++a) {
      // The hits' cubes came from the same product: a point within `reach` of a hit lands at
      // most one cube from it (a multiplication, not a division: 1.2M tests a BALM scan).
      // In [0, n) the floor is the truncation (std::floor without SSE4.1 costs ~25
      // instructions); outside it the point is refused either way.
      const double v = (x[a] - min_[a]) * inverse_cell_;
      if (!(v >= 0.0 && v < static_cast<double>(n_[a]))) return false;
      c[a] = static_cast<std::int64_t>(v);
    }
    return marks_[static_cast<std::size_t>((c[2] * n_[1] + c[1]) * n_[0] + c[0])];
  }

 private:
  double cell_ = 1.0, inverse_cell_ = 1.0;
  Eigen::Vector3d min_ = Eigen::Vector3d::Zero();
  std::int64_t n_[3] = {0, 0, 0};
  std::vector<bool> marks_;
};

/// makeSamples keeping only the free samples `near` says yes to (the filter inlined).
void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index, const NearHits& near,
                 std::vector<Sample>& out, std::vector<std::vector<Sample>>& parts);

/// How far short of its hit a ray's free evidence stops, m along the ray: its segments end
/// `free` short of the hit, then a tip segment (Sample::tip) runs on to `tip` short of it
/// (none when tip < 0 or tip >= free).
struct RayStop {
  double free = 0.0;
  double tip = -1.0;
};

/// One ray's free space: the one rule makeRaySegments and the free capsules (free_bundles)
/// share. From the origin along `direction` the ray is free to `extent` m (nothing when
/// extent <= 0), then its tip over [tip_from, tip_to] m (when has_tip). A ray longer than
/// max_range (>= 0) is cut there: free to max_range, without a stop or a tip.
struct RayFreeSpace {
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();
  double extent = 0.0, tip_from = 0.0, tip_to = 0.0;
  bool cut = false, has_tip = false;
};
/// Whether the ray to `point` takes a stop: it has a length and is not cut (the hits of
/// makeSamples, in order).
[[nodiscard]] bool takesStop(const Point3f& point, const Eigen::Vector3d& origin, double max_range);
/// The free space of the ray to `point`; false for a ray of no length (it takes no stop). A ray
/// that takes a stop takes stops[hit] and moves `hit` on (none, and the cursor stays, once
/// past the end of `stops`).
[[nodiscard]] bool rayFreeSpace(const Point3f& point, const Eigen::Vector3d& origin,
                                double max_range, std::span<const RayStop> stops, std::size_t& hit,
                                RayFreeSpace& out);

/// The free segments of a scan's rays (every ray of makeSamples, in the same order; a cut ray
/// is free all the way to max_range): [origin, hit - stop.free] split into equal segments of
/// at most `step`, then the tip. `stops` holds one entry per hit, in the order of the
/// occupied samples makeSamples returns (rays within max range).
[[nodiscard]] std::vector<Sample> makeRaySegments(const PointCloud& points_world,
                                                  const Point3f& origin_world, double step,
                                                  double max_range, std::span<const RayStop> stops);
/// The same into `out` (cleared, capacity kept).
void makeRaySegments(const PointCloud& points_world, const Point3f& origin_world, double step,
                     double max_range, std::span<const RayStop> stops, std::vector<Sample>& out);

/// A uniform double in [0, 1) from a counter (SplitMix64): reproducible random numbers.
[[nodiscard]] double uniformFromCounter(std::uint64_t counter);

}  // namespace densemap::kernel
