#include "densemap/kernel/kernel_map.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>

#include "densemap/geometry/stopwatch.hpp"
#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/kernel_function.hpp"

namespace densemap::kernel {

std::string_view kernelMethodName(KernelMethod method) {
  switch (method) {
    case KernelMethod::kAkimap:
      return "akimap";
    case KernelMethod::kBgk:
      return "bgk";
    case KernelMethod::kBgkl:
      return "bgkl";
  }
  return "unknown";
}

Expected<KernelMethod> parseKernelMethod(std::string_view name) {
  for (const auto m : {KernelMethod::kAkimap, KernelMethod::kBgk, KernelMethod::kBgkl}) {
    if (name == kernelMethodName(m)) return m;
  }
  return makeError("unknown kernel method '" + std::string(name) +
                   "' (expected akimap, bgk or bgkl)");
}

KernelOptions KernelOptions::defaults(KernelMethod method) {
  KernelOptions o;
  o.method = method;
  if (method == KernelMethod::kBgkl) {
    o.free_step = 0.3;
    o.sf2 = 0.1;
  }
  return o;
}

namespace {

/// One sample's kernel, ready to evaluate at cell centres.
struct Kernel {
  Eigen::Vector3d x;
  Eigen::Vector3d to;           // segment end (== x for point kernels)
  Eigen::Matrix3d h_inverse;    // anisotropic kernels: H^-1
  Eigen::Vector3d half_extent;  // bounding box of the support around [x, to]
  VoxelKey key_min, key_max;    // that box's voxels (set when the kernel is scheduled)
  double weight = 1.0;          // |H|^-1/2 (AKIMap) or sf2 (BGK)
  double inverse_length = 0.0;  // isotropic kernels: 1 / length scale; 0: anisotropic
  bool occupied = false;

  [[nodiscard]] double at(const Eigen::Vector3d& c) const {
    if (inverse_length == 0.0) {
      const Eigen::Vector3d d = c - x;
      return weight * sparseKernel(std::sqrt(std::max(0.0, d.dot(h_inverse * d))));
    }
    // Distance to the point, or to the segment [x, to].
    const Eigen::Vector3d seg = to - x;
    const double len2 = seg.squaredNorm();
    double t = len2 > 0.0 ? (c - x).dot(seg) / len2 : 0.0;
    t = std::clamp(t, 0.0, 1.0);
    return weight * sparseKernel((c - (x + t * seg)).norm() * inverse_length);
  }
};

/// The point samples of a scan bucketed in a dense grid of cubes (counting sort, bucket order
/// x fastest): a box search reads one contiguous run of samples per (y, z) row of buckets.
class SampleIndex {
 public:
  /// Buckets of `cell` metres, made coarser when the samples' box would need more than
  /// `max_cells` of them.
  SampleIndex(const std::vector<Sample>& samples, double cell, std::size_t max_cells)
      : samples_(samples) {
    Eigen::AlignedBox3d box;
    for (const Sample& s : samples) {
      if (!s.segment) box.extend(s.x);
    }
    if (box.isEmpty()) return;
    const Eigen::Vector3d size = box.sizes();
    cell_ = cell;
    while (cellCount(size) > max_cells) cell_ *= 1.5;
    min_ = box.min();
    for (int a = 0; a < 3; ++a) n_[a] = static_cast<std::int64_t>(size[a] / cell_) + 1;
    starts_.assign(static_cast<std::size_t>(n_[0] * n_[1] * n_[2]) + 1, 0);
    std::vector<std::uint32_t> bucket(samples.size(), 0);
    for (std::uint32_t i = 0; i < samples.size(); ++i) {
      if (samples[i].segment) continue;
      const auto c = cellOf(samples[i].x.array());
      bucket[i] = static_cast<std::uint32_t>((c[2] * n_[1] + c[1]) * n_[0] + c[0]);
      ++starts_[bucket[i] + 1];
    }
    for (std::size_t b = 1; b < starts_.size(); ++b) starts_[b] += starts_[b - 1];
    order_.resize(starts_.back());
    std::vector<std::uint32_t> next(starts_.begin(), starts_.end() - 1);
    for (std::uint32_t i = 0; i < samples.size(); ++i) {
      if (!samples[i].segment) order_[next[bucket[i]]++] = i;  // stable: ascending per bucket
    }
  }

  /// Calls f(index) for every point sample in the box centre +- half, in a fixed order.
  template <class F>
  void forEachInBox(const Eigen::Vector3d& centre, double half, F&& f) const {
    if (order_.empty()) return;
    const auto lo = cellOf(centre.array() - half);
    const auto hi = cellOf(centre.array() + half);
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
        const std::int64_t row = (z * n_[1] + y) * n_[0];
        const std::uint32_t from = starts_[static_cast<std::size_t>(row + lo[0])];
        const std::uint32_t to = starts_[static_cast<std::size_t>(row + hi[0] + 1)];
        for (std::uint32_t o = from; o < to; ++o) {
          const std::uint32_t i = order_[o];
          if (((samples_[i].x - centre).array().abs() <= half).all()) f(i);
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
      const double v = std::floor((p[a] - min_[a]) / cell_);
      c[a] = v < 0.0 ? 0 : (v >= static_cast<double>(n_[a]) ? n_[a] - 1 : static_cast<std::int64_t>(v));
    }
    return c;
  }

  const std::vector<Sample>& samples_;
  double cell_ = 1.0;
  Eigen::Vector3d min_ = Eigen::Vector3d::Zero();
  std::int64_t n_[3] = {1, 1, 1};
  std::vector<std::uint32_t> starts_;  // per bucket, into order_; one extra at the end
  std::vector<std::uint32_t> order_;   // point-sample indices by bucket
};

Kernel isotropicKernel(const Sample& s, const KernelOptions& o) {
  Kernel k;
  k.x = s.x;
  k.to = s.to;
  k.weight = o.sf2;
  k.inverse_length = 1.0 / o.length_scale;
  k.occupied = s.occupied;
  k.half_extent = Eigen::Vector3d::Constant(o.length_scale);
  return k;
}

/// AKIMap's kernel for sample i (Sec. 3.3.3): covariance of same-label neighbours in the search
/// box, then the scale minimising Eq. 3.7.
Kernel adaptiveKernel(std::size_t i, const std::vector<Sample>& samples, const SampleIndex& index,
                      const KernelOptions& o, double resolution,
                      std::vector<Neighbour>& neighbours) {
  const Sample& s = samples[i];
  const double range_ref = o.max_range > 0.0 ? o.max_range : o.search_range;
  const double half =
      resolution + (o.search_max - resolution) * std::clamp(s.range / range_ref, 0.0, 1.0);
  neighbours.clear();
  index.forEachInBox(s.x, half, [&](std::uint32_t j) {
    if (j != i) neighbours.push_back({samples[j].x, samples[j].occupied == s.occupied});
  });
  // The regulariser keeps flat kernels at least `min_thickness` (and a voxel) thick, one
  // standard deviation, so a surface's samples reach the centres of the cells they lie in; the
  // isotropic fallback spans half the search box.
  const double thickness = std::max(o.min_thickness, resolution);
  const double regulariser = thickness * thickness;
  const Eigen::Matrix3d sigma =
      neighbourCovariance(s.x, neighbours, regulariser, 0.25 * half * half);
  const double largest =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(sigma, Eigen::EigenvaluesOnly)
          .eigenvalues()
          .maxCoeff();
  // The support (sqrt(s * lambda) along each axis) stays inside the search box.
  const double s_max = std::max(1.0, half * half / largest);
  const double scale = fitScale(sigma, s.x, neighbours, 1.0 / 16.0, s_max);
  const Eigen::Matrix3d h = scale * sigma;
  Kernel k;
  k.x = s.x;
  k.to = s.x;
  k.h_inverse = h.inverse();
  k.weight = 1.0 / std::sqrt(h.determinant());
  k.occupied = s.occupied;
  k.half_extent = h.diagonal().cwiseSqrt();
  return k;
}

}  // namespace

KernelMap::KernelMap(double resolution_m, const KernelOptions& options)
    : grid_(resolution_m), options_(options) {}

KernelScanStats KernelMap::integrate(const PointCloud& points_world, const Point3f& origin_world,
                                     std::vector<VoxelKey>* touched) {
  KernelScanStats stats;
  auto t0 = std::chrono::steady_clock::now();
  SamplingOptions sampling;
  sampling.free_step = options_.free_step;
  sampling.max_range = options_.max_range;
  sampling.seed = options_.seed;
  sampling.free = options_.method == KernelMethod::kAkimap ? FreeSampling::kRandomPerInterval
                  : options_.method == KernelMethod::kBgk  ? FreeSampling::kRegular
                                                           : FreeSampling::kSegments;
  const std::vector<Sample> samples = makeSamples(points_world, origin_world, sampling, scans_);
  ++scans_;
  stats.samples = samples.size();
  stats.ms_samples = msSince(t0);

  std::vector<Kernel> kernels(samples.size());
  if (options_.method == KernelMethod::kAkimap) {
    // Buckets about the smallest search box (a voxel) at most 2^23 of them.
    const SampleIndex index(samples, std::max(grid_.resolution(), 0.25 * options_.search_max),
                            std::size_t{1} << 23);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, samples.size(), 256),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        std::vector<Neighbour> neighbours;
                        for (std::size_t i = range.begin(); i != range.end(); ++i) {
                          kernels[i] = adaptiveKernel(i, samples, index, options_,
                                                      grid_.resolution(), neighbours);
                        }
                      });
  } else {
    for (std::size_t i = 0; i < samples.size(); ++i) {
      kernels[i] = isotropicKernel(samples[i], options_);
    }
  }
  stats.ms_bandwidth = msSince(t0);

  // (block, kernel) pairs, sorted: each block then sums its kernels in sample order, whatever
  // the thread that runs it.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> pairs;
  for (std::uint32_t i = 0; i < kernels.size(); ++i) {
    Kernel& k = kernels[i];
    const Eigen::Vector3d lo = k.x.cwiseMin(k.to) - k.half_extent;
    const Eigen::Vector3d hi = k.x.cwiseMax(k.to) + k.half_extent;
    const auto klo = grid_.pointToKey(lo.cast<float>());
    const auto khi = grid_.pointToKey(hi.cast<float>());
    if (!klo || !khi) continue;  // outside the addressable range
    k.key_min = *klo;
    k.key_max = *khi;
    for (int bz = klo->z >> block::kShift; bz <= khi->z >> block::kShift; ++bz) {
      for (int by = klo->y >> block::kShift; by <= khi->y >> block::kShift; ++by) {
        for (int bx = klo->x >> block::kShift; bx <= khi->x >> block::kShift; ++bx) {
          const VoxelKey corner{static_cast<std::uint16_t>(bx << block::kShift),
                                static_cast<std::uint16_t>(by << block::kShift),
                                static_cast<std::uint16_t>(bz << block::kShift)};
          pairs.emplace_back(block::blockOf(corner), i);
        }
      }
    }
  }
  tbb::parallel_sort(pairs.begin(), pairs.end());
  std::vector<std::size_t> starts;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    if (p == 0 || pairs[p].first != pairs[p - 1].first) {
      starts.push_back(p);
      blocks_.try_emplace(pairs[p].first);  // created here, filled in parallel below
    }
  }
  starts.push_back(pairs.size());
  std::atomic<std::size_t> cell_updates{0};
  std::vector<block::BlockMask> reached(touched != nullptr ? starts.size() - 1 : 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, starts.size() - 1, 4),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::size_t updates = 0;
        for (std::size_t g = range.begin(); g != range.end(); ++g) {
          const std::uint64_t block_key = pairs[starts[g]].first;
          Block& b = blocks_.find(block_key)->second;
          for (std::size_t p = starts[g]; p < starts[g + 1]; ++p) {
            const Kernel& k = kernels[pairs[p].second];
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
            for (int z = z0; z <= z1; ++z) {
              for (int y = y0; y <= y1; ++y) {
                for (int x = x0; x <= x1; ++x) {
                  const VoxelKey key{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                                     static_cast<std::uint16_t>(z)};
                  const Eigen::Vector3d c(grid_.keyToCoord(key.x), grid_.keyToCoord(key.y),
                                          grid_.keyToCoord(key.z));
                  const double v = k.at(c);
                  if (!(v > 0.0)) continue;
                  const int cell = block::indexOf(key);
                  (k.occupied ? b.alpha : b.beta)[cell] += v;
                  block::setBit(b.known, cell);
                  if (touched != nullptr) block::setBit(reached[g], cell);
                  ++updates;
                }
              }
            }
          }
        }
        cell_updates += updates;
      });
  stats.cell_updates = cell_updates;
  if (touched != nullptr) {
    for (std::size_t g = 0; g + 1 < starts.size(); ++g) {
      const std::uint64_t block_key = pairs[starts[g]].first;
      for (int w = 0; w < block::kMaskWords; ++w) {
        for (std::uint64_t bits = reached[g][w]; bits != 0; bits &= bits - 1) {
          touched->push_back(block::keyOf(block_key, w * 64 + std::countr_zero(bits)));
        }
      }
    }
  }
  stats.ms_accumulate = msSince(t0);
  return stats;
}

void KernelMap::erase(const VoxelKey& key) {
  const auto it = blocks_.find(block::blockOf(key));
  if (it == blocks_.end()) return;
  const int cell = block::indexOf(key);
  block::clearBit(it->second.known, cell);
  it->second.alpha[cell] = 0.0;
  it->second.beta[cell] = 0.0;
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

std::size_t KernelMap::knownCells() const {
  std::size_t n = 0;
  for (const auto& [block_key, b] : blocks_) {
    for (const std::uint64_t w : b.known) n += static_cast<std::size_t>(std::popcount(w));
  }
  return n;
}

}  // namespace densemap::kernel
