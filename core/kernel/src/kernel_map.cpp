#include "densemap/kernel/kernel_map.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "densemap/geometry/stopwatch.hpp"
#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/kernel_function.hpp"
#include "free_bundles.hpp"
#include "free_traversal.hpp"
#include "radix_sort.hpp"

namespace densemap::kernel {

std::string_view kernelMethodName(KernelMethod method) {
  switch (method) {
    case KernelMethod::kAkimap:
      return "akimap";
    case KernelMethod::kBgk:
      return "bgk";
    case KernelMethod::kBgkl:
      return "bgkl";
    case KernelMethod::kAkimapRays:
      return "akimap_rays";
  }
  return "unknown";
}

Expected<KernelMethod> parseKernelMethod(std::string_view name) {
  for (const auto m : {KernelMethod::kAkimap, KernelMethod::kBgk, KernelMethod::kBgkl,
                       KernelMethod::kAkimapRays}) {
    if (name == kernelMethodName(m)) return m;
  }
  return makeError("unknown kernel method '" + std::string(name) +
                   "' (expected akimap, bgk, bgkl or akimap_rays)");
}

KernelOptions KernelOptions::defaults(KernelMethod method) {
  KernelOptions o;
  o.method = method;
  if (method == KernelMethod::kBgkl) {
    o.free_step = 0.3;
    o.sf2 = 0.1;
  }
  if (method == KernelMethod::kAkimapRays) {
    // Chosen on the oracle scenes at 0.1 and 0.05 m and the la3dm and AKIMap hold-outs (issue
    // 17 note): occupied kernels of weight 1 plus each hit's cell (0.7) and a 2-voxel kernel
    // around it (0.3); free segments of 0.3 m, radius 0.15 m, weight 0.4, stopping 0.2 m from the
    // surface, then a 0.1 m thin tip to 0.05 m from it.
    o.free_step = 0.3;
    o.length_scale = 0.15;
    o.sf2 = 0.4;
    o.occupied_weight = 1.0;
    o.hit_weight = 0.7;
    o.hit_kernel_weight = 0.3;
    o.hit_length_voxels = 2.0;
    o.free_margin = 0.2;
    o.max_margin = 1.0;
    o.tip_margin = 0.05;
    o.tip_length_scale = 0.1;
    // Issue 29: the same model at speed: each ray's free extent as one capsule (its joints'
    // extra evidence as a mean) and one adaptive kernel per voxel of 4+ hits; on la3dm's
    // hold-out and the oracle scenes (3 seeds) AUC within 0.0005 and MSE within +1.4% of a
    // kernel per ray piece and per hit (free_traversal=0, aggregate_hits=0), about 15x faster.
    o.free_traversal = true;
    o.aggregate_hits = true;
    // The capsules' outer 15% of radius hold 0.02% of the evidence in 28% of the voxels, but
    // cover voxels no other ray reaches on sparse scans: at 0.7 (1.0% of it, 51% of the voxels)
    // the oracle scenes' MSE rose 3.5-9% (cells left unknown); at 0.85 within 0.4% of the whole
    // kernel, la3dm's hold-out AUC within 0.0001 (3 seeds), with 72% of the voxel visits.
    o.free_reach = 0.85;
    o.free_bundles = true;
    // A voxel of 3 hits: one kernel at their mean too (4 before): every row of the dense-map
    // benchmark within 0.0001 AUC and 0.3% MSE (3 seeds), BALM's hold-out unchanged, ~10% fewer
    // kernels on a BALM scan. At 2 the grazing floor (AkimapRays test) lost its cells under
    // 22-degree rays, and la3dm's AUC fell 0.0001-0.0002.
    o.aggregate_min_hits = 3.0;
    // No free samples (issue 29's fourth stop): AKIMap's random free samples only shaped the
    // occupied kernels' scale, and without them every row of the dense-map benchmark moved by
    // at most 0.0001 AUC and +0.5% MSE (3 seeds), BALM's hold-out not at all (0.2 and 0.1 m),
    // while a BALM scan at 0.2 m took 62 ms instead of 93 (the samples, the index and the fits
    // over about a fifth of the points). negative_step=0.5 gives the earlier map.
    o.negative_step = 0.0;
  }
  return o;
}

Expected<void> applySettings(KernelOptions& options, const std::vector<std::string>& settings) {
  const std::pair<std::string_view, double KernelOptions::*> fields[] = {
      {"free_step", &KernelOptions::free_step},
      {"length_scale", &KernelOptions::length_scale},
      {"sf2", &KernelOptions::sf2},
      {"prior", &KernelOptions::prior},
      {"free_margin", &KernelOptions::free_margin},
      {"max_margin", &KernelOptions::max_margin},
      {"tip_margin", &KernelOptions::tip_margin},
      {"tip_length_scale", &KernelOptions::tip_length_scale},
      {"occupied_weight", &KernelOptions::occupied_weight},
      {"hit_weight", &KernelOptions::hit_weight},
      {"hit_length_voxels", &KernelOptions::hit_length_voxels},
      {"hit_kernel_weight", &KernelOptions::hit_kernel_weight},
      {"negative_step", &KernelOptions::negative_step},
      {"search_max", &KernelOptions::search_max},
      {"search_range", &KernelOptions::search_range},
      {"min_thickness", &KernelOptions::min_thickness},
      {"aggregate_min_hits", &KernelOptions::aggregate_min_hits},
      {"free_reach", &KernelOptions::free_reach}};
  for (const std::string& setting : settings) {
    const auto eq = setting.find('=');
    const std::string name = setting.substr(0, eq);
    if (name == "free_traversal" || name == "aggregate_hits" || name == "free_bundles") {
      const std::string value = eq == std::string::npos ? "" : setting.substr(eq + 1);
      if (value != "0" && value != "1") return makeError("'" + setting + "': expected 0 or 1");
      (name == "free_traversal"   ? options.free_traversal
       : name == "aggregate_hits" ? options.aggregate_hits
                                  : options.free_bundles) = value == "1";
      continue;
    }
    const auto field = std::find_if(std::begin(fields), std::end(fields),
                                    [&](const auto& f) { return f.first == name; });
    if (eq == std::string::npos || field == std::end(fields)) {
      return makeError("'" + setting + "' is not NAME=VALUE with a known kernel setting");
    }
    double value = 0.0;
    try {
      std::size_t used = 0;
      value = std::stod(setting.substr(eq + 1), &used);
      if (used != setting.size() - eq - 1) throw std::invalid_argument("trailing");
    } catch (const std::exception&) {
      return makeError("'" + setting + "': the value is not a number");
    }
    // Steps, scales and the prior must be positive; margins and hit weights may be 0.
    if (!std::isfinite(value) || value < 0.0 ||
        (value == 0.0 && name != "free_margin" && name != "tip_margin" && name != "hit_weight" &&
         name != "hit_kernel_weight") ||
        value > (name == "free_reach" ? 1.0 : 1000.0)) {
      return makeError("'" + setting + "': out of range");
    }
    options.*(field->second) = value;
  }
  return {};
}

namespace {

/// One sample's kernel, ready to evaluate at cell centres.
struct Kernel {
  Eigen::Vector3d x;
  Eigen::Vector3d to;  // segment end (== x for point kernels)
  // Anisotropic kernels: H^-1.
  Eigen::Matrix3d h_inverse = Eigen::Matrix3d::Zero();
  Eigen::Vector3d half_extent;  // bounding box of the support around [x, to]
  VoxelKey key_min, key_max;    // that box's voxels (set when the kernel is scheduled)
  double weight = 1.0;          // |H|^-1/2 (AKIMap) or sf2 (BGK)
  double inverse_length = 0.0;  // isotropic kernels: 1 / length scale; 0: anisotropic
  bool occupied = false;
  bool cell = false;  // `weight` on the one cell [key_min, key_max] (a hit's cell)

  /// The kernel's value at c, from the r^2 table (squaredKernel: no sqrt, no sincos).
  [[nodiscard]] double at(const Eigen::Vector3d& c, const SquaredKernelTable& table) const {
    if (cell) return weight;
    if (inverse_length == 0.0) {
      const Eigen::Vector3d d = c - x;
      return weight * table(d.dot(h_inverse * d));
    }
    // Distance to the point, or to the segment [x, to].
    const Eigen::Vector3d seg = to - x;
    const double len2 = seg.squaredNorm();
    double t = len2 > 0.0 ? (c - x).dot(seg) / len2 : 0.0;
    t = std::clamp(t, 0.0, 1.0);
    return weight * table((c - (x + t * seg)).squaredNorm() * inverse_length * inverse_length);
  }

  /// The x interval [lo, hi] (m) of the row at (y, z) outside which the kernel is 0: exact for
  /// ellipsoids, the infinite cylinder around a segment cut by its end planes (a superset of
  /// the capsule) otherwise. False when the row misses the support. Widened by a micrometre so
  /// that rounding never drops a cell the kernel reaches.
  [[nodiscard]] bool rowInterval(double y, double z, double& lo, double& hi) const {
    constexpr double kSlack = 1e-6;
    lo = -std::numeric_limits<double>::infinity();
    hi = std::numeric_limits<double>::infinity();
    if (cell) return true;
    const double dy = y - x.y(), dz = z - x.z();
    // a t^2 + 2 b t + c < 1 for t = cx - x.x (ellipsoid, or cylinder scaled to radius 1).
    double a = 0.0, b = 0.0, c = 0.0;
    if (inverse_length == 0.0) {
      const Eigen::Matrix3d& m = h_inverse;
      a = m(0, 0);
      b = m(0, 1) * dy + m(0, 2) * dz;
      c = m(1, 1) * dy * dy + 2.0 * m(1, 2) * dy * dz + m(2, 2) * dz * dz;
    } else {
      const Eigen::Vector3d seg = to - x;
      const double length = seg.norm();
      const double r2 = inverse_length * inverse_length;
      if (length > 0.0) {
        const Eigen::Vector3d u = seg / length;
        const double along_yz = dy * u.y() + dz * u.z();
        a = (1.0 - u.x() * u.x()) * r2;
        b = -u.x() * along_yz * r2;
        c = (dy * dy + dz * dz - along_yz * along_yz) * r2;
        // End planes: -radius <= t u.x + along_yz <= length + radius.
        const double radius = 1.0 / inverse_length;
        if (std::abs(u.x()) > 1e-12) {
          double t0 = (-radius - along_yz) / u.x(), t1 = (length + radius - along_yz) / u.x();
          if (t0 > t1) std::swap(t0, t1);
          lo = x.x() + t0 - kSlack;
          hi = x.x() + t1 + kSlack;
        } else if (along_yz < -radius || along_yz > length + radius) {
          return false;
        }
      } else {
        a = r2;
        c = (dy * dy + dz * dz) * r2;
      }
    }
    if (a <= 1e-12) return c < 1.0 + kSlack;  // the row runs along the axis
    const double disc = b * b - a * (c - 1.0);
    if (disc < 0.0) return false;
    const double root = std::sqrt(disc);
    lo = std::max(lo, x.x() + (-b - root) / a - kSlack);
    hi = std::min(hi, x.x() + (-b + root) / a + kSlack);
    return lo <= hi;
  }
};

/// The point samples of a scan bucketed in a dense grid of cubes (counting sort, bucket order
/// x fastest): a box search reads one contiguous run of samples per (y, z) row of buckets.
class SampleIndex {
 public:
  /// A point sample as the index holds it: its position and label beside its index, so that a
  /// search reads one contiguous run per row of buckets (not the samples, scattered).
  struct Entry {
    Eigen::Vector3d x;
    std::uint32_t index = 0;
    bool occupied = false;
  };
  /// The index's arrays, kept by the caller between scans (no fresh pages every scan).
  struct Storage {
    std::vector<std::uint32_t> starts;            // per bucket, into entries; see the constructor
    std::vector<Entry> entries;                   // the point samples by bucket
    std::vector<std::uint32_t> bucket;            // per sample
    std::vector<std::uint64_t> keys, keys_other;  // (bucket, index), sorted by the radix sort
    std::vector<std::uint32_t> counts;            // the radix sort's per-chunk counts
  };

  /// Buckets of `cell` metres, made coarser when the samples' box would need more than
  /// `max_cells` of them.
  SampleIndex(const std::vector<Sample>& samples, double cell, std::size_t max_cells,
              Storage& storage)
      : starts_(storage.starts), entries_(storage.entries) {
    // entries_ keeps its elements between scans (resized below, never cleared: constructing
    // 500k entries again cost 2 ms a scan); empty means no index.
    const Eigen::AlignedBox3d box = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, samples.size(), 16384), Eigen::AlignedBox3d(),
        [&](const tbb::blocked_range<std::size_t>& r, Eigen::AlignedBox3d b) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) {
            if (!samples[i].segment) b.extend(samples[i].x);
          }
          return b;
        },
        [](Eigen::AlignedBox3d a, const Eigen::AlignedBox3d& b) { return a.extend(b); });
    if (box.isEmpty()) {
      entries_.clear();
      return;
    }
    const Eigen::Vector3d size = box.sizes();
    cell_ = cell;
    while (cellCount(size) > max_cells) cell_ *= 1.5;
    min_ = box.min();
    for (int a = 0; a < 3; ++a) n_[a] = static_cast<std::int64_t>(size[a] / cell_) + 1;
    const auto buckets = static_cast<std::size_t>(n_[0] * n_[1] * n_[2]);
    std::vector<std::uint32_t>& bucket = storage.bucket;
    bucket.resize(samples.size());
    constexpr std::uint32_t kNone = ~std::uint32_t{0};  // a segment: not indexed
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 16384),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          if (samples[i].segment) {
                            bucket[i] = kNone;
                            continue;
                          }
                          const auto c = cellOf(samples[i].x.array());
                          bucket[i] =
                              static_cast<std::uint32_t>((c[2] * n_[1] + c[1]) * n_[0] + c[0]);
                        }
                      });
    // The indexed samples sorted by (bucket, index): a stable radix sort of (bucket, index)
    // pairs in index order (the order does not depend on the thread count).
    std::vector<std::uint64_t>& keys = storage.keys;
    keys.clear();
    for (std::uint32_t i = 0; i < samples.size(); ++i) {
      if (bucket[i] != kNone) keys.push_back((std::uint64_t{bucket[i]} << 32) | i);
    }
    radixSort(
        keys, storage.keys_other, static_cast<int>(std::bit_width(buckets)),
        [](std::uint64_t k) { return k >> 32; }, storage.counts);
    // starts[b]: the entries of buckets below b (b = 0 .. buckets), so bucket b is
    // [starts[b], starts[b + 1]); each written once, in parallel by the sorted entries.
    starts_.resize(buckets + 2);
    entries_.resize(keys.size());
    const auto bucketAt = [&keys](std::size_t i) {
      return static_cast<std::size_t>(keys[i] >> 32);
    };
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size(), 8192),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i != r.end(); ++i) {
                          const auto index = static_cast<std::uint32_t>(keys[i]);
                          entries_[i] = {samples[index].x, index, samples[index].occupied};
                          const std::size_t from = i == 0 ? 0 : bucketAt(i - 1) + 1;
                          for (std::size_t b = from; b <= bucketAt(i); ++b) {
                            starts_[b] = static_cast<std::uint32_t>(i);
                          }
                        }
                      });
    const std::size_t after = keys.empty() ? 0 : bucketAt(keys.size() - 1) + 1;
    std::fill(starts_.begin() + static_cast<std::ptrdiff_t>(after), starts_.end(),
              static_cast<std::uint32_t>(keys.size()));
  }

  /// Calls f(entry) for every point sample in the box centre +- half, in a fixed order.
  template <class F>
  void forEachInBox(const Eigen::Vector3d& centre, double half, F&& f) const {
    if (entries_.empty()) return;
    const auto lo = cellOf(centre.array() - half);
    const auto hi = cellOf(centre.array() + half);
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
        const std::int64_t row = (z * n_[1] + y) * n_[0];
        const std::uint32_t from = starts_[static_cast<std::size_t>(row + lo[0])];
        const std::uint32_t to = starts_[static_cast<std::size_t>(row + hi[0] + 1)];
        for (std::uint32_t o = from; o < to; ++o) {
          const Entry& e = entries_[o];
          if (((e.x - centre).array().abs() <= half).all()) f(e);
        }
      }
    }
  }

 private:
  [[nodiscard]] std::size_t cellCount(const Eigen::Vector3d& size) const {
    double n = 1.0;
    for (int a = 0; a < 3; ++a) n *= std::floor(size[a] / cell_) + 1.0;
    return n > 1e18 ? std::numeric_limits<std::size_t>::max() : static_cast<std::size_t>(n);
  }
  /// The bucket of p, clamped into the grid.
  [[nodiscard]] std::array<std::int64_t, 3> cellOf(const Eigen::Array3d& p) const {
    std::array<std::int64_t, 3> c{};
    for (int a = 0; a < 3; ++a) {
      // floor, clamped: below 1 the bucket is 0, and from there on the truncation is the floor
      // (std::floor without SSE4.1 is a sequence of ~25 instructions).
      const double v = (p[a] - min_[a]) / cell_;
      c[a] = v < 1.0 ? 0
                     : (v >= static_cast<double>(n_[a]) ? n_[a] - 1 : static_cast<std::int64_t>(v));
    }
    return c;
  }

  std::vector<std::uint32_t>& starts_;
  std::vector<Entry>& entries_;
  double cell_ = 1.0;
  Eigen::Vector3d min_ = Eigen::Vector3d::Zero();
  std::int64_t n_[3] = {1, 1, 1};
};

Kernel isotropicKernel(const Sample& s, const KernelOptions& o) {
  Kernel k;
  k.x = s.x;
  k.to = s.to;
  const double length = s.tip ? o.tip_length_scale : o.length_scale;
  k.weight = o.sf2;
  k.inverse_length = 1.0 / length;
  k.occupied = s.occupied;
  k.half_extent = Eigen::Vector3d::Constant(length);
  return k;
}

/// AKIMap's kernel for sample i (Sec. 3.3.3): covariance of same-label neighbours in the search
/// box, then the scale minimising Eq. 3.7.
/// When `normal` is given, it is set to the surface normal at the sample (the covariance's
/// least axis) where the same-label neighbourhood is flat (least spread under a quarter of
/// the middle one, regulariser aside), else to zero.
/// `s` is a sample or a voxel's mean hit; `left_out(entry)` says which samples are not its
/// neighbours (the sample itself, or the voxel's own hits).
template <class LeftOut>
Kernel adaptiveKernel(const Sample& s, LeftOut&& left_out, const std::vector<Sample>& samples,
                      const SampleIndex& index, const KernelOptions& o, double resolution,
                      std::vector<Neighbour>& neighbours, Eigen::Vector3d* normal = nullptr) {
  const double range_ref = o.max_range > 0.0 ? o.max_range : o.search_range;
  const double half =
      resolution + (o.search_max - resolution) * std::clamp(s.range / range_ref, 0.0, 1.0);
  neighbours.clear();
  index.forEachInBox(s.x, half, [&](const SampleIndex::Entry& e) {
    if (!left_out(e)) neighbours.push_back({e.x, e.occupied == s.occupied});
  });
  // The regulariser keeps flat kernels at least `min_thickness` (and a voxel) thick, one
  // standard deviation, so a surface's samples reach the centres of the cells they lie in; the
  // isotropic fallback spans half the search box.
  const double thickness = std::max(o.min_thickness, resolution);
  const double regulariser = thickness * thickness;
  const Eigen::Matrix3d sigma =
      neighbourCovariance(s.x, neighbours, regulariser, 0.25 * half * half);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(
      sigma, normal != nullptr ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
  const double largest = eigen.eigenvalues().maxCoeff();  // ascending: [0] least, [2] largest
  if (normal != nullptr) {
    const std::size_t same = static_cast<std::size_t>(std::count_if(
        neighbours.begin(), neighbours.end(), [](const Neighbour& n) { return n.same_label; }));
    const double least = eigen.eigenvalues()[0] - regulariser;
    const double middle = eigen.eigenvalues()[1] - regulariser;
    *normal = same >= 3 && middle > 4.0 * std::max(least, 0.0) && middle > 0.0
                  ? Eigen::Vector3d(eigen.eigenvectors().col(0))
                  : Eigen::Vector3d::Zero();
  }
  // The support (sqrt(s * lambda) along each axis) stays inside the search box.
  const double s_max = std::max(1.0, half * half / largest);
  const double scale = fitScale(sigma, s.x, neighbours, 1.0 / 16.0, s_max);
  const Eigen::Matrix3d h = scale * sigma;
  Kernel k;
  k.x = s.x;
  k.to = s.x;
  k.h_inverse = h.inverse();
  k.weight = o.method == KernelMethod::kAkimapRays && o.occupied_weight > 0.0
                 ? o.occupied_weight
                 : 1.0 / std::sqrt(h.determinant());
  k.occupied = s.occupied;
  k.half_extent = h.diagonal().cwiseSqrt();
  return k;
}

/// The hits of a scan: the points within max range (the occupied samples of makeSamples).
std::vector<Eigen::Vector3d> hitsOf(const PointCloud& points_world, const Eigen::Vector3d& origin,
                                    double max_range) {
  std::vector<Eigen::Vector3d> hits;
  for (const Point3f& p : points_world) {
    const double length = (p.cast<double>() - origin).norm();
    if (length > 0.0 && (max_range < 0.0 || length <= max_range)) hits.push_back(p.cast<double>());
  }
  return hits;
}

/// Where kAkimapRays' free evidence along a ray stops: `free_margin` and `tip_margin` from the
/// surface, measured along its normal (a distance d from the surface is d / cos(incidence)
/// along the ray, at most max_margin), or along the ray where no normal is known (zero).
RayStop rayStop(const Eigen::Vector3d& ray, const Eigen::Vector3d& normal, const KernelOptions& o) {
  const double cosine = std::abs(ray.dot(normal));
  const auto along = [&](double margin) {
    if (margin < 0.0 || normal.isZero()) return margin;
    return std::min(margin / std::max(cosine, 1e-6), std::max(o.max_margin, margin));
  };
  return {along(o.free_margin), along(o.tip_margin)};
}

/// kAkimapRays' direct hit evidence: per hit, its cell (hit_weight) and an isotropic kernel of
/// hit_length_voxels (hit_kernel_weight); with `counts`, `positions` are voxels' mean hits, each
/// standing for that many hits (the cell's evidence is then exactly the hits' sum).
void appendHitKernels(const std::vector<Eigen::Vector3d>& positions,
                      const std::vector<double>* counts, const KernelOptions& o, double resolution,
                      std::vector<Kernel>& kernels) {
  const double radius = o.hit_length_voxels * resolution;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const double count = counts != nullptr ? (*counts)[i] : 1.0;
    Kernel k;
    k.x = k.to = positions[i];
    k.occupied = true;
    if (o.hit_weight > 0.0) {
      k.weight = o.hit_weight * count;
      k.cell = true;
      k.half_extent.setZero();
      kernels.push_back(k);
    }
    if (o.hit_kernel_weight > 0.0) {
      k.weight = o.hit_kernel_weight * count;
      k.cell = false;
      k.half_extent.setConstant(radius);
      k.inverse_length = 1.0 / radius;
      kernels.push_back(k);
    }
  }
}

/// kAkimapRays with aggregate_hits: the adaptive kernels of a scan's hits (`hits`: indices of
/// the occupied samples) and each hit's ray stop. A voxel with at least `aggregate_min_hits`
/// hits gets one kernel at their mean, weighing their count, fitted to the neighbourhood
/// outside the voxel; its normal sets its rays' stops. Other voxels keep a kernel per hit (a
/// mean would lose the spread of a few hits, which is their shape: a grazing floor's).
/// `means` and `counts`: where the direct hit evidence goes and how many hits it stands for.
void adaptiveVoxelKernels(const VoxelGrid& grid, const KernelOptions& options,
                          const std::vector<Sample>& samples,
                          const std::vector<std::uint32_t>& hits, const SampleIndex& index,
                          const Eigen::Vector3d& origin, std::vector<Kernel>& kernels,
                          std::vector<RayStop>& stops, std::vector<Eigen::Vector3d>& means,
                          std::vector<double>& counts) {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> by_voxel(hits.size());
  // A hit's voxel, packed in 48 bits (outside the addressable range: one reserved value
  // above them, so such hits sort last).
  const auto voxelOf = [&grid](const Eigen::Vector3d& x) {
    const auto key = grid.pointToKey(x.cast<float>());
    return key ? key->packed() : std::uint64_t{1} << 48;
  };
  for (std::uint32_t h = 0; h < hits.size(); ++h) by_voxel[h] = {voxelOf(samples[hits[h]].x), h};
  // By voxel, hits in order within each (stable; made in hit order).
  std::vector<std::pair<std::uint64_t, std::uint32_t>> by_voxel_other;
  std::vector<std::uint32_t> radix_counts;
  radixSort(
      by_voxel, by_voxel_other, 49, [](const auto& pair) { return pair.first; }, radix_counts);
  // Groups of hits by voxel, and where each group's kernels go (one, or one per hit).
  const auto min_hits = static_cast<std::uint32_t>(std::max(1.0, options.aggregate_min_hits));
  std::vector<std::uint32_t> group_starts, outputs{0};
  for (std::size_t p = 0; p <= by_voxel.size(); ++p) {
    if (p == by_voxel.size() || p == 0 || by_voxel[p].first != by_voxel[p - 1].first) {
      if (!group_starts.empty()) {
        const std::uint32_t n = static_cast<std::uint32_t>(p) - group_starts.back();
        outputs.push_back(outputs.back() + (n >= min_hits ? 1 : n));
      }
      group_starts.push_back(static_cast<std::uint32_t>(p));
    }
  }
  const std::size_t groups = group_starts.size() - 1;
  kernels.resize(outputs.back());
  means.resize(outputs.back());
  counts.resize(outputs.back());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, groups, 64),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<Neighbour> neighbours;
        Eigen::Vector3d normal;
        for (std::size_t g = range.begin(); g != range.end(); ++g) {
          const std::uint32_t first = group_starts[g], last = group_starts[g + 1];
          std::uint32_t out = outputs[g];
          if (last - first < min_hits) {  // a kernel per hit, as without aggregation
            for (std::uint32_t p = first; p < last; ++p, ++out) {
              const std::uint32_t h = by_voxel[p].second, i = hits[h];
              kernels[out] = adaptiveKernel(
                  samples[i], [i](const SampleIndex::Entry& e) { return e.index == i; }, samples,
                  index, options, grid.resolution(), neighbours, &normal);
              means[out] = samples[i].x;
              counts[out] = 1.0;
              stops[h] = rayStop((samples[i].x - origin).normalized(), normal, options);
            }
            continue;
          }
          Sample centre;
          centre.occupied = true;
          for (std::uint32_t p = first; p < last; ++p) {
            const Sample& h = samples[hits[by_voxel[p].second]];
            centre.x += h.x;
            centre.range += h.range;
          }
          const double count = last - first;
          centre.x /= count;
          centre.to = centre.x;
          centre.range /= count;
          const std::uint64_t own = by_voxel[first].first;
          // The voxel's own hits, recognised by their position (no lookup per neighbour): a
          // point clearly outside the voxel's cube (by more than a millimetre and a float's
          // rounding at that distance from the origin) is not one; only points near its faces
          // take the key's own test.
          const VoxelKey own_key = VoxelKey::fromPacked(own);
          const Eigen::Vector3d own_centre(grid.keyToCoord(own_key.x), grid.keyToCoord(own_key.y),
                                           grid.keyToCoord(own_key.z));
          const double clearly_out = 0.5 * grid.resolution() + 1e-3 +
                                     2e-7 * own_centre.cwiseAbs().maxCoeff();  // float's step
          Kernel k = adaptiveKernel(
              centre,
              [&](const SampleIndex::Entry& e) {
                if (!e.occupied) return false;
                if (((e.x - own_centre).array().abs() > clearly_out).any()) return false;
                return voxelOf(e.x) == own;
              },
              samples, index, options, grid.resolution(), neighbours, &normal);
          k.weight *= count;
          kernels[out] = k;
          means[out] = centre.x;
          counts[out] = count;
          for (std::uint32_t p = first; p < last; ++p) {
            const std::uint32_t h = by_voxel[p].second;
            stops[h] = rayStop((samples[hits[h]].x - origin).normalized(), normal, options);
          }
        }
      });
}
}  // namespace

/// A scan's buffers, kept between scans: a fresh vector per scan costs a page fault per 4 KiB
/// (about 6% of a BALM scan's time was the kernel's fault handler).
struct KernelMap::Scratch {
  std::vector<std::vector<Sample>> sample_parts;
  SampleIndex::Storage index;
  std::vector<Kernel> kernels;
  std::vector<FreeExtent> free_extents;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs;
  std::vector<std::size_t> pair_offsets;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs_other;
  std::vector<std::uint32_t> radix_counts;
  std::vector<Block*> free_targets;
  FreeBundleBuffers bundles;
};

KernelMap::KernelMap(double resolution_m, const KernelOptions& options)
    : grid_(resolution_m),
      options_(options),
      free_(std::make_unique<FreeTraversal>()),
      scratch_(std::make_unique<Scratch>()) {}
KernelMap::~KernelMap() = default;
KernelMap::KernelMap(KernelMap&&) noexcept = default;
KernelMap& KernelMap::operator=(KernelMap&&) noexcept = default;

KernelScanStats KernelMap::integrate(const PointCloud& points_world, const Point3f& origin_world,
                                     std::vector<BlockCells>* touched) {
  KernelScanStats stats;
  auto t0 = std::chrono::steady_clock::now();
  drawSamples(points_world, origin_world);
  ++scans_;
  stats.ms_samples = msSince(t0);
  t0 = std::chrono::steady_clock::now();
  fitKernels(points_world, origin_world);
  stats.samples = scratch_->kernels.size();
  stats.ms_kernels = msSince(t0);
  t0 = std::chrono::steady_clock::now();
  // Blocks reached by the kernels and by the free capsules (when `touched` is wanted).
  std::vector<std::pair<std::uint64_t, block::BlockMask>> reached;
  auto* reached_or_null = touched != nullptr ? &reached : nullptr;
  stats.cell_updates = accumulateKernels(reached_or_null);
  stats.ms_occupied = msSince(t0);
  const std::vector<FreeExtent>& free_extents = scratch_->free_extents;
  if (!free_extents.empty()) {
    t0 = std::chrono::steady_clock::now();
    stats.free_visits = free_->accumulate(grid_, free_extents, options_.free_reach);
    stats.ms_free = msSince(t0);
    t0 = std::chrono::steady_clock::now();
    applyFree(reached_or_null);
  }
  if (touched != nullptr) mergeReached(reached, *touched);
  if (!free_extents.empty()) stats.ms_apply = msSince(t0);
  return stats;
}

/// The scan's samples into samples_ (hits; and free samples for the kinds that draw them).
void KernelMap::drawSamples(const PointCloud& points_world, const Point3f& origin_world) {
  SamplingOptions sampling;
  sampling.free_step = options_.free_step;
  sampling.max_range = options_.max_range;
  sampling.seed = options_.seed;
  sampling.free = options_.method == KernelMethod::kBgk    ? FreeSampling::kRegular
                  : options_.method == KernelMethod::kBgkl ? FreeSampling::kSegments
                                                           : FreeSampling::kRandomPerInterval;
  const bool rays = options_.method == KernelMethod::kAkimapRays;
  if (rays && !(options_.negative_step > 0.0)) {
    sampling.free = FreeSampling::kNone;
    makeSamples(points_world, origin_world, sampling, scans_, nullptr, samples_,
                scratch_->sample_parts);
  } else if (rays) {
    // Free samples only shape the occupied kernels, through the search boxes around hits:
    // the others are never drawn (the same kernels, far fewer samples on long rays).
    sampling.free_step = options_.negative_step;
    const NearHits near_hits(hitsOf(points_world, origin_world.cast<double>(), options_.max_range),
                             std::max(options_.search_max, grid_.resolution()));
    makeSamples(points_world, origin_world, sampling, scans_, near_hits, samples_,
                scratch_->sample_parts);
  } else {
    makeSamples(points_world, origin_world, sampling, scans_, nullptr, samples_,
                scratch_->sample_parts);
  }
}

/// The scan's kernels into scratch_->kernels (kAkimapRays: and its free extents into
/// scratch_->free_extents).
void KernelMap::fitKernels(const PointCloud& points_world, const Point3f& origin_world) {
  const bool rays = options_.method == KernelMethod::kAkimapRays;
  const std::vector<Sample>& samples = samples_;
  std::vector<Kernel>& kernels = scratch_->kernels;
  std::vector<FreeExtent>& free_extents = scratch_->free_extents;
  kernels.clear();
  free_extents.clear();
  if (options_.method == KernelMethod::kAkimap || rays) {
    // Buckets about the smallest search box (a voxel), at most 8 per sample and 2^21 in all
    // (coarser over a large scan: the counting sort writes every bucket each scan, and the
    // table is kept between scans).
    const std::size_t max_buckets =
        std::clamp(8 * samples.size(), std::size_t{1} << 16, std::size_t{1} << 21);
    const SampleIndex index(samples, std::max(grid_.resolution(), 0.25 * options_.search_max),
                            max_buckets, scratch_->index);
    // kAkimapRays: kernels for the occupied samples only (then the free segments).
    std::vector<std::uint32_t> centres;
    for (std::uint32_t i = 0; i < samples.size(); ++i) {
      if (!rays || samples[i].occupied) centres.push_back(i);
    }
    std::vector<RayStop> stops(rays ? centres.size() : 0);
    const Eigen::Vector3d origin = origin_world.cast<double>();
    std::vector<Eigen::Vector3d> hit_positions;  // kAkimapRays' direct hit evidence
    std::vector<double> hit_counts;
    const bool aggregate = rays && options_.aggregate_hits;
    if (aggregate) {
      adaptiveVoxelKernels(grid_, options_, samples, centres, index, origin, kernels, stops,
                           hit_positions, hit_counts);
    } else {
      if (rays) {
        for (const std::uint32_t i : centres) hit_positions.push_back(samples[i].x);
      }
      kernels.resize(centres.size());
      tbb::parallel_for(
          tbb::blocked_range<std::size_t>(0, centres.size(), 256),
          [&](const tbb::blocked_range<std::size_t>& range) {
            std::vector<Neighbour> neighbours;
            Eigen::Vector3d normal;
            for (std::size_t c = range.begin(); c != range.end(); ++c) {
              const std::uint32_t i = centres[c];
              kernels[c] = adaptiveKernel(
                  samples[i], [i](const SampleIndex::Entry& e) { return e.index == i; }, samples,
                  index, options_, grid_.resolution(), neighbours, rays ? &normal : nullptr);
              if (rays) {
                stops[c] = rayStop((samples[centres[c]].x - origin).normalized(), normal, options_);
              }
            }
          });
    }
    // The fast path takes one capsule per ray (or per bundle of rays ending in one voxel),
    // walked by FreeTraversal, and its tip; the plain path a segment kernel per piece of ray.
    const bool traverse = rays && options_.free_traversal;
    segments_.clear();
    if (rays && !traverse) {
      makeRaySegments(points_world, origin_world, options_.free_step, options_.max_range, stops,
                      segments_);
    }
    const std::vector<Sample>& segments = segments_;
    // Two hit kernels per position (a voxel's mean when aggregated: far fewer than the hits).
    kernels.reserve(kernels.size() + 2 * hit_positions.size() + segments.size());
    if (rays) {
      appendHitKernels(hit_positions, aggregate ? &hit_counts : nullptr, options_,
                       grid_.resolution(), kernels);
    }
    for (const Sample& s : segments) kernels.push_back(isotropicKernel(s, options_));
    if (traverse) {
      // The segment kernels overlap where consecutive pieces meet: within `length_scale` of each
      // joint a voxel on the ray gets a second value, on average 2 * length_scale * (integral
      // of k over [0, 1] = 1/3) more evidence per `free_step` of ray. One extent per ray has no
      // joints, so its weight carries that mean; a tip is one piece, as before.
      const double joints = 1.0 + 2.0 * options_.length_scale / 3.0 / options_.free_step;
      const CapsuleShape shape{.free_radius_m = options_.length_scale,
                               .free_weight = options_.sf2 * joints,
                               .tip_radius_m = options_.tip_length_scale,
                               .tip_weight = options_.sf2};
      freeExtents(points_world, origin, options_.max_range, stops, grid_, shape,
                  options_.free_bundles, scratch_->bundles, free_extents);
    }
  } else {
    kernels.reserve(samples.size());
    for (const Sample& s : samples) kernels.push_back(isotropicKernel(s, options_));
  }
}

/// The (block, kernel) pairs of every block each kernel's box overlaps, into scratch_->pairs
/// sorted by block, kernels in order within each (counts, offsets, then the pairs in place, in
/// parallel; a stable radix sort).
void KernelMap::sortKernelPairs() {
  std::vector<Kernel>& kernels = scratch_->kernels;  // their key boxes are set here
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& pairs = scratch_->pairs;
  // Each kernel's box of blocks (in parallel: counts, offsets, then the pairs in place).
  std::vector<std::size_t>& pair_offsets = scratch_->pair_offsets;
  pair_offsets.assign(kernels.size() + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, kernels.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        Kernel& k = kernels[i];
                        // a cell kernel: x itself
                        const Eigen::Vector3d lo = k.x.cwiseMin(k.to) - k.half_extent;
                        const Eigen::Vector3d hi = k.x.cwiseMax(k.to) + k.half_extent;
                        const auto klo = grid_.pointToKey(lo.cast<float>());
                        const auto khi = grid_.pointToKey(hi.cast<float>());
                        if (!klo || !khi) continue;  // outside the addressable range
                        k.key_min = *klo;
                        k.key_max = *khi;
                        std::size_t n = 1;
                        for (int a = 0; a < 3; ++a) {
                          n *= static_cast<std::size_t>(((*khi)[a] >> block::kShift) -
                                                        ((*klo)[a] >> block::kShift) + 1);
                        }
                        pair_offsets[i + 1] = n;
                      }
                    });
  for (std::size_t i = 0; i < kernels.size(); ++i) pair_offsets[i + 1] += pair_offsets[i];
  pairs.resize(pair_offsets.back());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, kernels.size(), 1024),
      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          std::size_t out = pair_offsets[i];
          if (out == pair_offsets[i + 1]) continue;
          const VoxelKey& klo = kernels[i].key_min;
          const VoxelKey& khi = kernels[i].key_max;
          for (int bz = klo.z >> block::kShift; bz <= khi.z >> block::kShift; ++bz) {
            for (int by = klo.y >> block::kShift; by <= khi.y >> block::kShift; ++by) {
              for (int bx = klo.x >> block::kShift; bx <= khi.x >> block::kShift; ++bx) {
                const VoxelKey corner{static_cast<std::uint16_t>(bx << block::kShift),
                                      static_cast<std::uint16_t>(by << block::kShift),
                                      static_cast<std::uint16_t>(bz << block::kShift)};
                pairs[out++] = {block::blockOf(corner), static_cast<std::uint32_t>(i)};
              }
            }
          }
        }
      });
  // By block, kernels in order within each (the pairs were made in kernel order): block keys
  // are 39 bits.
  radixSort(
      pairs, scratch_->pairs_other, 39, [](const auto& pair) { return pair.first; },
      scratch_->radix_counts);
}

/// Sums the kernels into their blocks: each block's kernels in kernel order, blocks in
/// parallel. Returns the (cell, kernel) contributions; appends each block's reached cells to
/// `reached` when given.
std::size_t KernelMap::accumulateKernels(
    std::vector<std::pair<std::uint64_t, block::BlockMask>>* reached_blocks) {
  // (block, kernel) pairs, sorted: each block then sums its kernels in sample order, whatever
  // the thread that runs it.
  sortKernelPairs();
  const std::vector<Kernel>& kernels = scratch_->kernels;
  const std::vector<std::pair<std::uint64_t, std::uint32_t>>& pairs = scratch_->pairs;
  std::vector<std::size_t> starts;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    if (p == 0 || pairs[p].first != pairs[p - 1].first) {
      starts.push_back(p);
      blocks_.try_emplace(pairs[p].first);  // created here, filled in parallel below
    }
  }
  starts.push_back(pairs.size());
  std::atomic<std::size_t> cell_updates{0};
  const SquaredKernelTable& table = squaredKernel();
  std::vector<block::BlockMask> reached(reached_blocks != nullptr ? starts.size() - 1 : 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, starts.size() - 1, 4),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::size_t updates = 0;
        // A block's sums of this scan in double (in kernel order), added to its float evidence
        // once the block is done.
        std::array<double, block::kVoxels> sum_alpha{}, sum_beta{};
        for (std::size_t g = range.begin(); g != range.end(); ++g) {
          const std::uint64_t block_key = pairs[starts[g]].first;
          Block& b = blocks_.find(block_key)->second;
          block::BlockMask summed{};
          for (std::size_t p = starts[g]; p < starts[g + 1]; ++p) {
            const Kernel& k = kernels[pairs[p].second];
            const bool point = !k.cell && k.inverse_length != 0.0 && k.to == k.x;
            const VoxelKey& klo = k.key_min;
            const VoxelKey& khi = k.key_max;
            const VoxelKey base = block::keyOf(block_key, 0);
            const auto range_of = [&](int axis, std::uint16_t from, std::uint16_t to) {
              const int b0 = base[axis];
              return std::pair<int, int>(std::max<int>(from, b0),
                                         std::min<int>(to, b0 + block::kEdge - 1));
            };
            const auto [x0, x1] = range_of(0, klo.x, khi.x);
            const auto [y0, y1] = range_of(1, klo.y, khi.y);
            const auto [z0, z1] = range_of(2, klo.z, khi.z);
            const double res = grid_.resolution();
            const double base_x = grid_.keyToCoord(static_cast<std::uint16_t>(x0));
            for (int z = z0; z <= z1; ++z) {
              for (int y = y0; y <= y1; ++y) {
                double lo = 0.0, hi = 0.0;
                if (options_.whole_boxes) {
                  lo = -std::numeric_limits<double>::infinity();
                  hi = std::numeric_limits<double>::infinity();
                } else if (!k.rowInterval(grid_.keyToCoord(static_cast<std::uint16_t>(y)),
                                          grid_.keyToCoord(static_cast<std::uint16_t>(z)), lo,
                                          hi)) {
                  continue;
                }
                const int from = lo <= base_x ? x0
                                              : static_cast<int>(std::min<double>(
                                                    x1 + 1, x0 + std::ceil((lo - base_x) / res)));
                const int to = static_cast<int>(
                    std::clamp<double>(x0 + std::floor((hi - base_x) / res), x0 - 1, x1));
                const double cy = grid_.keyToCoord(static_cast<std::uint16_t>(y));
                const double cz = grid_.keyToCoord(static_cast<std::uint16_t>(z));
                for (int x = from; x <= to; ++x) {
                  const VoxelKey key{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                     static_cast<std::uint16_t>(z)};
                  const Eigen::Vector3d c(grid_.keyToCoord(key.x), cy, cz);
                  // A point kernel (x == to) skips the segment's projection: t = 0 there, so
                  // the same value, bit for bit.
                  const double v = point ? k.weight * table((c - k.x).squaredNorm() *
                                                            k.inverse_length * k.inverse_length)
                                         : k.at(c, table);
                  if (!(v > 0.0)) continue;
                  const int cell = block::indexOf(key);
                  (k.occupied ? sum_alpha : sum_beta)[cell] += v;
                  block::setBit(summed, cell);
                  ++updates;
                }
              }
            }
          }
          block::forEachSetBit(summed, [&](int cell) {
            b.alpha[cell] += static_cast<float>(sum_alpha[cell]);
            b.beta[cell] += static_cast<float>(sum_beta[cell]);
            sum_alpha[cell] = 0.0;
            sum_beta[cell] = 0.0;
          });
          for (int w = 0; w < block::kMaskWords; ++w) b.known[w] |= summed[w];
          if (reached_blocks != nullptr) reached[g] = summed;
        }
        cell_updates += updates;
      });
  if (reached_blocks != nullptr) {
    for (std::size_t g = 0; g + 1 < starts.size(); ++g) {
      reached_blocks->emplace_back(pairs[starts[g]].first, reached[g]);
    }
  }
  return cell_updates.load();
}

/// Adds the free traversal's sums to the blocks' beta; appends the blocks it reached to
/// `reached` when given.
void KernelMap::applyFree(std::vector<std::pair<std::uint64_t, block::BlockMask>>* reached_blocks) {
  // The blocks found (or made) one by one, then filled in parallel: one block per task.
  const std::vector<const FreeTraversal::Block*>& free_blocks = free_->blocks();
  std::vector<Block*>& targets = scratch_->free_targets;
  targets.resize(free_blocks.size());
  const double inverse_scale = 1.0 / free_->scale();
  for (std::size_t i = 0; i < free_blocks.size(); ++i) {
    targets[i] = &blocks_[free_blocks[i]->key];
    if (reached_blocks != nullptr)
      reached_blocks->emplace_back(free_blocks[i]->key, free_blocks[i]->mask);
  }
  tbb::parallel_for(std::size_t{0}, free_blocks.size(), [&](std::size_t i) {
    const FreeTraversal::Block& f = *free_blocks[i];
    Block& b = *targets[i];
    block::forEachSetBit(f.mask, [&](int cell) {
      b.beta[cell] += static_cast<float>(static_cast<double>(f.sum[cell]) * inverse_scale);
      block::setBit(b.known, cell);
    });
  });
}

/// `reached` by block key (stably), each block's masks merged, appended to `touched`.
void KernelMap::mergeReached(std::vector<std::pair<std::uint64_t, block::BlockMask>>& reached,
                             std::vector<BlockCells>& touched) {
  std::stable_sort(reached.begin(), reached.end(),
                   [](const auto& x, const auto& y) { return x.first < y.first; });
  for (std::size_t i = 0; i < reached.size();) {
    const std::uint64_t block_key = reached[i].first;
    BlockCells& merged = touched.emplace_back(BlockCells{.key = block_key});
    for (; i < reached.size() && reached[i].first == block_key; ++i) {
      for (int w = 0; w < block::kMaskWords; ++w) merged.cells[w] |= reached[i].second[w];
    }
  }
}

void KernelMap::erase(const VoxelKey& key) {
  const auto it = blocks_.find(block::blockOf(key));
  if (it == blocks_.end()) return;
  const int cell = block::indexOf(key);
  block::clearBit(it->second.known, cell);
  it->second.alpha[cell] = 0.0F;
  it->second.beta[cell] = 0.0F;
}

std::size_t KernelMap::evictBlocks(const std::function<bool(const Point3f&)>& keep) {
  const std::size_t before = blocks_.size();
  std::erase_if(blocks_,
                [&](const auto& entry) { return !keep(block::centreOf(grid_, entry.first)); });
  return before - blocks_.size();
}

std::optional<double> KernelMap::probability(const VoxelKey& key) const {
  const auto it = blocks_.find(block::blockOf(key));
  if (it == blocks_.end()) return std::nullopt;
  const int cell = block::indexOf(key);
  if (!block::testBit(it->second.known, cell)) return std::nullopt;
  const double alpha = options_.prior + it->second.alpha[cell];
  const double beta = options_.prior + it->second.beta[cell];
  return alpha / (alpha + beta);
}

void KernelMap::blockLogOdds(std::uint64_t block_key, const block::BlockMask& cells,
                             std::array<float, block::kVoxels>& log_odds) const {
  const auto it = blocks_.find(block_key);
  block::forEachSetBit(cells, [&](int cell) {
    // probability(), cell by cell: unknown is p = 0.5
    double p = 0.5;
    if (it != blocks_.end() && block::testBit(it->second.known, cell)) {
      const double alpha = options_.prior + it->second.alpha[cell];
      const double beta = options_.prior + it->second.beta[cell];
      p = alpha / (alpha + beta);
    }
    log_odds[cell] = static_cast<float>(std::log(p / (1.0 - p)));
  });
}

void KernelMap::forEachKnown(const std::function<void(const VoxelKey&, double)>& f) const {
  for (const auto& [block_key, b] : blocks_) {
    for (int cell = 0; cell < block::kVoxels; ++cell) {
      if (!block::testBit(b.known, cell)) continue;
      const double alpha = options_.prior + b.alpha[cell];
      const double beta = options_.prior + b.beta[cell];
      f(block::keyOf(block_key, cell), alpha / (alpha + beta));
    }
  }
}

KernelEvidence KernelMap::evidence() const {
  KernelEvidence e;
  e.method = options_.method;
  e.resolution_m = grid_.resolution();
  e.scans = scans_;
  std::vector<std::uint64_t> order;
  order.reserve(blocks_.size());
  for (const auto& entry : blocks_) order.push_back(entry.first);
  std::sort(order.begin(), order.end());  // a file does not depend on the hash's order
  const std::size_t n = knownCells();
  e.keys.reserve(n);
  e.alpha.reserve(n);
  e.beta.reserve(n);
  for (const std::uint64_t block_key : order) {
    const Block& b = blocks_.at(block_key);
    block::forEachSetBit(b.known, [&](int cell) {
      e.keys.push_back(block::keyOf(block_key, cell));
      e.alpha.push_back(b.alpha[static_cast<std::size_t>(cell)]);
      e.beta.push_back(b.beta[static_cast<std::size_t>(cell)]);
    });
  }
  return e;
}

Expected<void> KernelMap::restore(const KernelEvidence& e) {
  if (e.method != options_.method) {
    return makeError("kernel evidence of " + std::string(kernelMethodName(e.method)) + ", not " +
                     std::string(kernelMethodName(options_.method)));
  }
  if (e.resolution_m != grid_.resolution()) {
    return makeError("kernel evidence at " + std::to_string(e.resolution_m) + " m, not " +
                     std::to_string(grid_.resolution()) + " m");
  }
  if (e.alpha.size() != e.keys.size() || e.beta.size() != e.keys.size()) {
    return makeError("kernel evidence arrays differ in length");
  }
  // Held as float: a value beyond float's range is refused, not stored as infinity.
  const auto valid = [](double v) {
    return std::isfinite(v) && v >= 0.0 && v <= std::numeric_limits<float>::max();
  };
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    if (!valid(e.alpha[i]) || !valid(e.beta[i])) {
      return makeError("kernel evidence has a negative or non-finite value");
    }
  }
  blocks_.clear();
  for (std::size_t i = 0; i < e.keys.size(); ++i) {
    Block& b = blocks_[block::blockOf(e.keys[i])];
    const int cell = block::indexOf(e.keys[i]);
    b.alpha[static_cast<std::size_t>(cell)] = static_cast<float>(e.alpha[i]);
    b.beta[static_cast<std::size_t>(cell)] = static_cast<float>(e.beta[i]);
    block::setBit(b.known, cell);
  }
  scans_ = e.scans;
  return {};
}

std::size_t KernelMap::memoryBytes() const {
  // A node of the hash (the block, its key, the next pointer) and a bucket per block.
  std::size_t bytes = blocks_.size() * (sizeof(Block) + 2 * sizeof(void*) + sizeof(std::uint64_t)) +
                      blocks_.bucket_count() * sizeof(void*);
  bytes += (samples_.capacity() + segments_.capacity()) * sizeof(Sample);
  for (const auto& part : scratch_->sample_parts) bytes += part.capacity() * sizeof(Sample);
  bytes += scratch_->index.starts.capacity() * sizeof(std::uint32_t) +
           scratch_->index.entries.capacity() * sizeof(SampleIndex::Entry) +
           scratch_->index.bucket.capacity() * sizeof(std::uint32_t) +
           (scratch_->index.keys.capacity() + scratch_->index.keys_other.capacity()) *
               sizeof(std::uint64_t) +
           scratch_->index.counts.capacity() * sizeof(std::uint32_t);
  const FreeBundleBuffers& fb = scratch_->bundles;
  bytes += (fb.hit_of.capacity() + fb.takes.capacity()) * sizeof(std::uint32_t) +
           (fb.rays.capacity() + fb.rays_other.capacity()) *
               sizeof(std::pair<std::uint64_t, std::uint32_t>) +
           fb.radix_counts.capacity() * sizeof(std::uint32_t) +
           (fb.group_starts.capacity() + fb.offsets.capacity()) * sizeof(std::size_t);
  bytes += scratch_->kernels.capacity() * sizeof(Kernel) +
           scratch_->free_extents.capacity() * sizeof(FreeExtent) +
           (scratch_->pairs.capacity() + scratch_->pairs_other.capacity()) *
               sizeof(std::pair<std::uint64_t, std::uint32_t>) +
           scratch_->radix_counts.capacity() * sizeof(std::uint32_t);
  return bytes + free_->memoryBytes();
}

std::size_t KernelMap::knownCells() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks_) {
    for (const std::uint64_t w : b.known) n += static_cast<std::size_t>(std::popcount(w));
  }
  return n;
}

}  // namespace densemap::kernel
