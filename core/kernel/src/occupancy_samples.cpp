#include "densemap/kernel/occupancy_samples.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace densemap::kernel {

double uniformFromCounter(std::uint64_t counter) {
  std::uint64_t z = counter + 0x9E3779B97F4A7C15ULL;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * 0x1p-53;
}

std::vector<Sample> makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                                const SamplingOptions& options, std::uint64_t scan_index,
                                const std::function<bool(const Eigen::Vector3d&)>& keep_free) {
  std::vector<Sample> samples;
  makeSamples(points_world, origin_world, options, scan_index, keep_free, samples);
  return samples;
}

namespace {

/// The first `chunks` parts, in order, into `out`: in parallel, each part copied to its offset
/// (a serial copy of tens of MB would be a large share of the samples' stage).
void concatenate(const std::vector<std::vector<Sample>>& parts, std::size_t chunks,
                 std::vector<Sample>& out) {
  std::vector<std::size_t> offsets(chunks + 1, 0);
  for (std::size_t c = 0; c < chunks; ++c) offsets[c + 1] = offsets[c] + parts[c].size();
  out.resize(offsets[chunks]);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::copy(parts[c].begin(), parts[c].end(),
              out.begin() + static_cast<std::ptrdiff_t>(offsets[c]));
  });
}

/// The samples of points [first, last) of a scan, appended to `samples`.
template <class Keep>
void samplesOfRays(const PointCloud& points_world, std::size_t first, std::size_t last,
                   const Eigen::Vector3d& origin, const SamplingOptions& options,
                   std::uint64_t scan_index, const Keep& keep_free, std::vector<Sample>& samples) {
  const double step = options.free_step;
  for (std::size_t ray_index = first; ray_index < last; ++ray_index) {
    const std::uint64_t ray_key = options.seed * 0xD1B54A32D192ED03ULL ^
                                  scan_index * 0x8CB92BA72F3D8DD7ULL ^
                                  (std::uint64_t{ray_index} << 20);
    const Eigen::Vector3d point = points_world[ray_index].cast<double>();
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
    if (options.free == FreeSampling::kNone) continue;
    const auto intervals = static_cast<std::uint64_t>(std::floor(length / step));
    if (options.free == FreeSampling::kRandomPerInterval) {
      // The common case in a tight loop: the point drawn, tested, and only then a sample.
      for (std::uint64_t k = 0; k < intervals; ++k) {
        const double start = static_cast<double>(k) * step;
        const double range = start + uniformFromCounter(ray_key + k) * step;
        const Eigen::Vector3d x = origin + range * direction;
        if (!keep_free(x)) continue;
        samples.push_back({x, x, range, false, false, false});
      }
      continue;
    }
    for (std::uint64_t k = 0; k < intervals; ++k) {
      const double start = static_cast<double>(k) * step;
      Sample s;
      s.occupied = false;
      if (options.free == FreeSampling::kRegular) {
        s.range = start + 0.5 * step;
        s.x = origin + s.range * direction;
        s.to = s.x;
      } else {  // kSegments
        s.range = start;
        s.x = origin + start * direction;
        s.to = origin + (start + step) * direction;
        s.segment = true;
      }
      if (!keep_free(s.x)) continue;
      samples.push_back(s);
    }
  }
}

}  // namespace

void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index,
                 const std::function<bool(const Eigen::Vector3d&)>& keep_free,
                 std::vector<Sample>& samples) {
  std::vector<std::vector<Sample>> parts;
  makeSamples(points_world, origin_world, options, scan_index, keep_free, samples, parts);
}

namespace {

/// makeSamples with the free samples' filter inlined (a call through std::function per 0.5 m
/// of every ray was a tenth of the samples' stage).
template <class Keep>
void makeSamplesKeeping(const PointCloud& points_world, const Point3f& origin_world,
                        const SamplingOptions& options, std::uint64_t scan_index,
                        const Keep& keep_free, std::vector<Sample>& samples,
                        std::vector<std::vector<Sample>>& parts) {
  samples.clear();
  const Eigen::Vector3d origin = origin_world.cast<double>();
  // Fixed chunks of rays in parallel, concatenated in ray order: the same samples, in the same
  // order, whatever the thread count.
  constexpr std::size_t kChunk = 4096;
  const std::size_t chunks = (points_world.size() + kChunk - 1) / kChunk;
  if (chunks <= 1) {
    samplesOfRays(points_world, 0, points_world.size(), origin, options, scan_index, keep_free,
                  samples);
    return;
  }
  if (parts.size() < chunks) parts.resize(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    parts[c].clear();
    samplesOfRays(points_world, c * kChunk, std::min(points_world.size(), (c + 1) * kChunk), origin,
                  options, scan_index, keep_free, parts[c]);
  });
  concatenate(parts, chunks, samples);
}

}  // namespace

void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index,
                 const std::function<bool(const Eigen::Vector3d&)>& keep_free,
                 std::vector<Sample>& samples, std::vector<std::vector<Sample>>& parts) {
  makeSamplesKeeping(
      points_world, origin_world, options, scan_index,
      [&keep_free](const Eigen::Vector3d& x) { return !keep_free || keep_free(x); }, samples,
      parts);
}

void makeSamples(const PointCloud& points_world, const Point3f& origin_world,
                 const SamplingOptions& options, std::uint64_t scan_index, const NearHits& near,
                 std::vector<Sample>& samples, std::vector<std::vector<Sample>>& parts) {
  makeSamplesKeeping(points_world, origin_world, options, scan_index, near, samples, parts);
}

NearHits::NearHits(const std::vector<Eigen::Vector3d>& hits, double reach) : cell_(reach) {
  if (hits.empty() || !(reach > 0.0)) return;
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& h : hits) box.extend(h);
  // A margin of one cube on each side holds the dilation.
  min_ = box.min().array() - cell_;
  for (int a = 0; a < 3; ++a) n_[a] = static_cast<std::int64_t>(box.sizes()[a] / cell_) + 3;
  // Very sparse hits over a huge box: coarser cubes (still a superset).
  while (static_cast<double>(n_[0]) * static_cast<double>(n_[1]) * static_cast<double>(n_[2]) >
         double{1 << 26}) {
    cell_ *= 2.0;
    min_ = box.min().array() - cell_;
    for (int a = 0; a < 3; ++a) n_[a] = static_cast<std::int64_t>(box.sizes()[a] / cell_) + 3;
  }
  inverse_cell_ = 1.0 / cell_;
  // The hits' own cubes first, then each such cube dilated once (a cube holds many hits: 27
  // marks per cube, not per hit).
  const auto cells = static_cast<std::size_t>(n_[0] * n_[1] * n_[2]);
  std::vector<std::uint8_t> centres(cells, 0);
  for (const Eigen::Vector3d& h : hits) {
    std::int64_t c[3];
    for (int a = 0; a < 3; ++a) c[a] = static_cast<std::int64_t>((h[a] - min_[a]) * inverse_cell_);
    centres[static_cast<std::size_t>((c[2] * n_[1] + c[1]) * n_[0] + c[0])] = 1;
  }
  marks_.assign(cells, false);
  for (std::size_t i = 0; i < cells; ++i) {
    if (centres[i] == 0) continue;
    const auto c0 = static_cast<std::int64_t>(i);
    const std::int64_t cx = c0 % n_[0], cy = (c0 / n_[0]) % n_[1], cz = c0 / (n_[0] * n_[1]);
    for (std::int64_t z = cz - 1; z <= cz + 1; ++z) {
      for (std::int64_t y = cy - 1; y <= cy + 1; ++y) {
        for (std::int64_t x = cx - 1; x <= cx + 1; ++x) {
          marks_[static_cast<std::size_t>((z * n_[1] + y) * n_[0] + x)] = true;
        }
      }
    }
  }
}

std::vector<Sample> makeRaySegments(const PointCloud& points_world, const Point3f& origin_world,
                                    double step, double max_range, std::span<const RayStop> stops) {
  std::vector<Sample> segments;
  makeRaySegments(points_world, origin_world, step, max_range, stops, segments);
  return segments;
}

namespace {

/// A ray of this length is cut at max_range (>= 0; < 0: never).
bool isCut(double length, double max_range) { return max_range >= 0.0 && length > max_range; }

}  // namespace

bool takesStop(const Point3f& point, const Eigen::Vector3d& origin, double max_range) {
  const double length = (point.cast<double>() - origin).norm();
  return length > 0.0 && !isCut(length, max_range);
}

bool rayFreeSpace(const Point3f& point, const Eigen::Vector3d& origin, double max_range,
                  std::span<const RayStop> stops, std::size_t& hit, RayFreeSpace& out) {
  Eigen::Vector3d direction = point.cast<double>() - origin;
  double length = direction.norm();
  if (!(length > 0.0)) return false;
  out.direction = direction / length;
  out.cut = isCut(length, max_range);
  RayStop stop;
  if (out.cut) {
    length = max_range;
  } else if (hit < stops.size()) {
    stop = stops[hit++];
  }
  out.extent = length - stop.free;
  out.has_tip = !out.cut && stop.tip >= 0.0 && stop.tip < stop.free && length - stop.tip > 0.0;
  out.tip_from = std::max(0.0, out.extent);
  out.tip_to = length - stop.tip;
  return true;
}

namespace {

/// The segments of points [first, last) (their first hit's stop is stops[hit]), appended.
void raySegmentsOf(const PointCloud& points_world, std::size_t first, std::size_t last,
                   const Eigen::Vector3d& origin, double step, double max_range,
                   std::span<const RayStop> stops, std::size_t hit, std::vector<Sample>& segments) {
  RayFreeSpace ray;
  for (std::size_t i = first; i < last; ++i) {
    if (!rayFreeSpace(points_world[i], origin, max_range, stops, hit, ray)) continue;
    if (ray.extent > 0.0) {
      const double pieces = std::ceil(ray.extent / step);
      const double piece = ray.extent / pieces;
      for (double k = 0.0; k < pieces; k += 1.0) {
        Sample s;
        s.x = origin + k * piece * ray.direction;
        s.to = origin + (k + 1.0) * piece * ray.direction;
        s.range = k * piece;
        s.segment = true;
        segments.push_back(s);
      }
    }
    if (ray.has_tip) {
      Sample s;
      s.range = ray.tip_from;
      s.x = origin + s.range * ray.direction;
      s.to = origin + ray.tip_to * ray.direction;
      s.segment = true;
      s.tip = true;
      segments.push_back(s);
    }
  }
}

}  // namespace

void makeRaySegments(const PointCloud& points_world, const Point3f& origin_world, double step,
                     double max_range, std::span<const RayStop> stops,
                     std::vector<Sample>& segments) {
  segments.clear();
  const Eigen::Vector3d origin = origin_world.cast<double>();
  // Fixed chunks of rays in parallel (each starting at its first hit's stop), concatenated in
  // ray order: the same segments in the same order whatever the thread count.
  constexpr std::size_t kChunk = 4096;
  const std::size_t chunks = (points_world.size() + kChunk - 1) / kChunk;
  if (chunks <= 1) {
    raySegmentsOf(points_world, 0, points_world.size(), origin, step, max_range, stops, 0,
                  segments);
    return;
  }
  // Each chunk's first stop: the rays before it that take one.
  std::vector<std::size_t> first_hit(chunks + 1, 0);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::size_t n = 0;
    for (std::size_t i = c * kChunk; i < std::min(points_world.size(), (c + 1) * kChunk); ++i) {
      n += takesStop(points_world[i], origin, max_range) ? 1 : 0;
    }
    first_hit[c + 1] = n;
  });
  for (std::size_t c = 0; c < chunks; ++c) first_hit[c + 1] += first_hit[c];
  std::vector<std::vector<Sample>> parts(chunks);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    raySegmentsOf(points_world, c * kChunk, std::min(points_world.size(), (c + 1) * kChunk), origin,
                  step, max_range, stops, first_hit[c], parts[c]);
  });
  concatenate(parts, chunks, segments);
}

}  // namespace densemap::kernel
