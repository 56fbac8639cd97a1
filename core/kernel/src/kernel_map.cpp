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
#include <optional>
#include <stdexcept>
#include <string>

#include "densemap/geometry/rounding.hpp"
#include "densemap/geometry/stopwatch.hpp"
#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/kernel_function.hpp"
#include "free_bundles.hpp"
#include "free_traversal.hpp"
#include "kernel_fit.hpp"
#include "kernel_scratch.hpp"
#include "radix_sort.hpp"

namespace densemap::kernel {

using detail::adaptiveKernel;
using detail::adaptiveVoxelKernels;
using detail::appendHitKernels;
using detail::hitsOf;
using detail::isotropicKernel;
using detail::Kernel;
using detail::rayStop;
using detail::RowIntervals;
using detail::sharedHitStencils;

namespace {

/// One adaptive kernel per centre sample (kAkimap; kAkimapRays without aggregate_hits, which
/// then also takes each hit's ray stop into `stops`), fitted to the other samples.
void samplesKernels(const KernelOptions& options, double resolution,
                    const std::vector<Sample>& samples, const std::vector<std::uint32_t>& centres,
                    const SampleIndex& index, const Eigen::Vector3d& origin,
                    std::vector<Kernel>& kernels, std::vector<RayStop>* stops) {
  kernels.resize(centres.size());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, centres.size(), 256),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<Neighbour> neighbours;
        Eigen::Vector3d normal;
        for (std::size_t c = range.begin(); c != range.end(); ++c) {
          const std::uint32_t i = centres[c];
          kernels[c] = adaptiveKernel(
              samples[i], [i](const SampleIndex::Entry& e) { return e.index == i; }, index, options,
              resolution, neighbours, stops != nullptr ? &normal : nullptr);
          if (stops != nullptr) {
            (*stops)[c] = rayStop((samples[i].x - origin).normalized(), normal, options);
          }
        }
      });
}

/// The cells a kernel reaches in one row of a block (its 8 cells share a mask word), gathered
/// in a register and written to the block's mask once: a bit set in memory per cell would make
/// each cell wait for the last one's store, and the count too, which the mask may alias.
class RowBits {
 public:
  explicit RowBits(int cell_in_row) : word_(cell_in_row >> 6) {}
  void set(int cell) { bits_ |= std::uint64_t{1} << (cell & 63); }
  void into(block::BlockMask& mask) const { mask[static_cast<std::size_t>(word_)] |= bits_; }

 private:
  int word_;
  std::uint64_t bits_ = 0;
};

/// An isotropic point kernel's values on the cells [x0, x1] x [y0, y1] x [z0, z1] of one block
/// (in z, y, x order), added to the block's sums: each axis' squared offsets once, then per
/// cell the squared distance as squaredNorm sums it ((dx^2 + dy^2) + dz^2, then times 1 / l
/// twice: the same value, bit for bit), no row interval and no centre per cell. A row whose
/// dy^2 + dz^2 is already outside the support is skipped (adding dx^2 >= 0 cannot bring it
/// back). The hits' 2-voxel kernels (one per voxel of hits) took 60% of the occupied stage on
/// BALM at 0.2 m through the rows' square roots and each cell's centre.
void accumulatePointKernel(const VoxelGrid& grid, const Kernel& k, int x0, int x1, int y0, int y1,
                           int z0, int z1, const SquaredKernelTable& table,
                           std::array<double, block::kVoxels>& sum_alpha,
                           std::array<double, block::kVoxels>& sum_beta, block::BlockMask& summed,
                           std::size_t& updates) {
  std::array<double, block::kEdge> sx{}, sy{}, sz{};
  const auto squares = [&](int axis, int from, int to, std::array<double, block::kEdge>& out) {
    for (int i = from; i <= to; ++i) {
      const double d = grid.keyToCoord(static_cast<std::uint16_t>(i)) - k.x[axis];
      out[static_cast<std::size_t>(i - from)] = d * d;
    }
  };
  squares(0, x0, x1, sx);
  squares(1, y0, y1, sy);
  squares(2, z0, z1, sz);
  const double inverse_length = k.inverse_length;
  std::array<double, block::kVoxels>& sums = k.occupied ? sum_alpha : sum_beta;
  std::size_t n = 0;
  for (int z = z0; z <= z1; ++z) {
    const double dz2 = sz[static_cast<std::size_t>(z - z0)];
    for (int y = y0; y <= y1; ++y) {
      const double dy2 = sy[static_cast<std::size_t>(y - y0)];
      if (!((dy2 + dz2) * inverse_length * inverse_length < 1.0)) continue;
      const int row =
          block::indexOf(VoxelKey{static_cast<std::uint16_t>(x0), static_cast<std::uint16_t>(y),
                                  static_cast<std::uint16_t>(z)});
      RowBits bits(row);
      for (int x = x0; x <= x1; ++x) {
        const double u =
            (sx[static_cast<std::size_t>(x - x0)] + dy2 + dz2) * inverse_length * inverse_length;
        const double v = k.weight * table(u);
        if (!(v > 0.0)) continue;
        const int cell = row + (x - x0);
        sums[static_cast<std::size_t>(cell)] += v;
        bits.set(cell);
        ++n;
      }
      bits.into(summed);
    }
  }
  updates += n;
}

/// A tabled hit kernel's values (HitStencils) on the cells [x0, x1] x [y0, y1] x [z0, z1] of
/// one block, added to the block's alpha sums: per row only the stretch where the kernel is
/// not 0, per cell a product.
void accumulateStencilKernel(const detail::HitStencils& stencils, const Kernel& k, int x0, int x1,
                             int y0, int y1, int z0, int z1,
                             std::array<double, block::kVoxels>& sum_alpha,
                             block::BlockMask& summed, std::size_t& updates) {
  const VoxelKey& c = k.stencil_key;
  const int reach = stencils.reach();
  std::size_t n = 0;
  // The pairs' box comes from the kernel's support in float: a row past the table (at the
  // support's edge, where the kernel is 0) is skipped, never read.
  for (int z = std::max(z0, c.z - reach); z <= std::min(z1, c.z + reach); ++z) {
    for (int y = std::max(y0, c.y - reach); y <= std::min(y1, c.y + reach); ++y) {
      const int dy = y - c.y, dz = z - c.z;
      const auto [first, last] = stencils.rowExtent(k.stencil, dy, dz);
      const int from = std::max(x0, c.x + first), to = std::min(x1, c.x + last);
      if (from > to) continue;
      const double* const values = stencils.row(k.stencil, dy, dz);
      const int shift = reach - c.x;  // values[x + shift]: offset x - c.x
      const int row =
          block::indexOf(VoxelKey{static_cast<std::uint16_t>(x0), static_cast<std::uint16_t>(y),
                                  static_cast<std::uint16_t>(z)}) -
          x0;
      RowBits bits(row + from);
      for (int x = from; x <= to; ++x) {
        const double v = k.weight * values[x + shift];
        if (!(v > 0.0)) continue;
        sum_alpha[static_cast<std::size_t>(row + x)] += v;
        bits.set(row + x);
        ++n;
      }
      bits.into(summed);
    }
  }
  updates += n;
}

/// Adds kernel `k`'s evidence to the cells of [x0, x1] x [y0, y1] x [z0, z1] (one block) that
/// it reaches, row by row (only each row's stretch the kernel can reach, unless
/// `options.whole_boxes`); `point`: an isotropic point kernel (no segment to project on).
void accumulateKernel(const VoxelGrid& grid, const KernelOptions& options, const Kernel& k,
                      bool point, int x0, int x1, int y0, int y1, int z0, int z1,
                      const SquaredKernelTable& table,
                      std::array<double, block::kVoxels>& sum_alpha,
                      std::array<double, block::kVoxels>& sum_beta, block::BlockMask& summed,
                      std::size_t& updates) {
  const double res = grid.resolution();
  const double inverse_res = 1.0 / res;
  const double base_x = grid.keyToCoord(static_cast<std::uint16_t>(x0));
  const RowIntervals rows(k);
  std::size_t n = 0;
  for (int z = z0; z <= z1; ++z) {
    for (int y = y0; y <= y1; ++y) {
      double lo = 0.0, hi = 0.0;
      if (options.whole_boxes) {
        lo = -std::numeric_limits<double>::infinity();
        hi = std::numeric_limits<double>::infinity();
      } else if (!rows(grid.keyToCoord(static_cast<std::uint16_t>(y)),
                       grid.keyToCoord(static_cast<std::uint16_t>(z)), lo, hi)) {
        continue;
      }
      // The row's cells [from, to] within [x0, x1]: ceil and floor of the interval's
      // ends in cells, clamped first (an end may be infinite).
      // (A product by 1 / res, not a quotient: an ulp apart, inside the interval's
      // slack, so the same cells get evidence.)
      const int from =
          lo <= base_x ? x0
                       : x0 + ceilToInt(std::min<double>(x1 + 1 - x0, (lo - base_x) * inverse_res));
      const int to =
          x0 + floorToInt(std::clamp<double>((hi - base_x) * inverse_res, -1.0, x1 - x0));
      const double cy = grid.keyToCoord(static_cast<std::uint16_t>(y));
      const double cz = grid.keyToCoord(static_cast<std::uint16_t>(z));
      RowBits bits(
          block::indexOf(VoxelKey{static_cast<std::uint16_t>(x0), static_cast<std::uint16_t>(y),
                                  static_cast<std::uint16_t>(z)}));
      for (int x = from; x <= to; ++x) {
        const VoxelKey key{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                           static_cast<std::uint16_t>(z)};
        const Eigen::Vector3d c(grid.keyToCoord(key.x), cy, cz);
        // A point kernel (x == to) skips the segment's projection: t = 0 there, so
        // the same value, bit for bit.
        // A tabled hit kernel evaluated (the plain path of the table's values).
        const double v =
            k.stencil >= 0
                ? k.weight *
                      (options.hit_kernel_weight *
                           table((c - k.x).squaredNorm() * k.inverse_length * k.inverse_length) +
                       (key == k.stencil_key ? options.hit_weight : 0.0))
            : point
                ? k.weight * table((c - k.x).squaredNorm() * k.inverse_length * k.inverse_length)
                : k.at(c, table);
        if (!(v > 0.0)) continue;
        const int cell = block::indexOf(key);
        (k.occupied ? sum_alpha : sum_beta)[cell] += v;
        bits.set(cell);
        ++n;
      }
      bits.into(summed);
    }
  }
  updates += n;
}

}  // namespace

KernelMap::KernelMap(double resolution_m, const KernelOptions& options, BlockStore* store)
    : grid_(resolution_m),
      options_(options),
      own_store_(store == nullptr ? std::make_unique<BlockStore>() : nullptr),
      store_(store == nullptr ? own_store_.get() : store),
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
  free_->release();
  scratch_->releaseFree();
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
    // (coarser over a large scan: the counting sort writes every bucket each scan).
    const std::size_t max_buckets =
        std::clamp(8 * samples.size(), std::size_t{1} << 16, std::size_t{1} << 21);
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
    {
      const SampleIndex index(samples, std::max(grid_.resolution(), 0.25 * options_.search_max),
                              max_buckets, scratch_->index);
      if (aggregate) {
        adaptiveVoxelKernels(grid_, options_, samples, centres, index, origin, kernels, stops,
                             hit_positions, hit_counts);
      } else {
        if (rays) {
          for (const std::uint32_t i : centres) hit_positions.push_back(samples[i].x);
        }
        samplesKernels(options_, grid_.resolution(), samples, centres, index, origin, kernels,
                       rays ? &stops : nullptr);
      }
    }
    // The samples and their index are done with: their memory serves the stages after.
    release(centres);
    release(samples_);
    scratch_->releaseSamples();
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
      // Tabled (hit_stencil_steps) where there is a hit kernel.
      const int steps = static_cast<int>(options_.hit_stencil_steps);
      const bool tabled = steps > 0 && options_.hit_kernel_weight > 0.0;
      if (tabled && scratch_->hit_stencils == nullptr) {
        scratch_->hit_stencils = sharedHitStencils(options_.hit_length_voxels, steps,
                                                   options_.hit_kernel_weight, options_.hit_weight);
      }
      appendHitKernels(hit_positions, aggregate ? &hit_counts : nullptr, options_, grid_,
                       tabled ? scratch_->hit_stencils : nullptr, kernels);
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
      // Bundled by the map's voxels, or by coarser cubes (free_bundle_m).
      const std::optional<VoxelGrid> cubes =
          options_.free_bundle_m > grid_.resolution()
              ? std::optional<VoxelGrid>(VoxelGrid(options_.free_bundle_m))
              : std::nullopt;
      const VoxelGrid* bundle_grid = !options_.free_bundles ? nullptr : cubes ? &*cubes : &grid_;
      if (bundle_grid != nullptr && options_.free_bundle_levels >= 1.0) {
        freeExtentsTree(points_world, origin, options_.max_range, stops, shape, *bundle_grid,
                        static_cast<int>(options_.free_bundle_levels), scratch_->bundles,
                        free_extents);
      } else {
        freeExtents(points_world, origin, options_.max_range, stops, shape, bundle_grid,
                    scratch_->bundles, free_extents);
      }
      scratch_->releaseBundles();
    }
    release(segments_);
  } else {
    kernels.reserve(samples.size());
    for (const Sample& s : samples) kernels.push_back(isotropicKernel(s, options_));
    release(samples_);
    scratch_->releaseSamples();
  }
}

/// The (block, kernel) pairs of every block each kernel's box overlaps, into scratch_->pairs
/// sorted by block, kernels in order within each (counts, offsets, then the pairs in place, in
/// parallel; a stable radix sort); the blocks as ranks in their box (scratch_->block_ranks).
void KernelMap::sortKernelPairs() {
  std::vector<Kernel>& kernels = scratch_->kernels;  // their key boxes are set here
  std::vector<std::pair<std::uint64_t, std::uint32_t>>& pairs = scratch_->pairs;
  // Each kernel's box of blocks (in parallel: counts, offsets, then the pairs in place), and
  // the box of them all (block coordinates: least x, y, z, then greatest).
  std::vector<std::size_t>& pair_offsets = scratch_->pair_offsets;
  pair_offsets.assign(kernels.size() + 1, 0);
  using Box = std::array<std::uint64_t, 6>;
  constexpr std::uint64_t kMost = 0x1fff;  // block coordinates are 13 bits
  const Box box = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, kernels.size(), 1024), Box{kMost, kMost, kMost, 0, 0, 0},
      [&](const tbb::blocked_range<std::size_t>& range, Box b) {
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
            const std::uint64_t from = (*klo)[a] >> block::kShift, to = (*khi)[a] >> block::kShift;
            n *= static_cast<std::size_t>(to - from + 1);
            b[a] = std::min(b[a], from);
            b[3 + a] = std::max(b[3 + a], to);
          }
          pair_offsets[i + 1] = n;
        }
        return b;
      },
      [](Box x, const Box& y) {
        for (int a = 0; a < 3; ++a) {
          x[a] = std::min(x[a], y[a]);
          x[3 + a] = std::max(x[3 + a], y[3 + a]);
        }
        return x;
      });
  BlockRanks& ranks = scratch_->block_ranks;
  ranks = BlockRanks{};
  if (box[0] <= box[3]) {
    ranks.low = {box[0], box[1], box[2]};
    ranks.bits_x = static_cast<int>(std::bit_width(box[3] - box[0]));
    ranks.bits_y = static_cast<int>(std::bit_width(box[4] - box[1]));
    ranks.bits_z = static_cast<int>(std::bit_width(box[5] - box[2]));
  }
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
          for (std::uint64_t bz = klo.z >> block::kShift;
               bz <= std::uint64_t{khi.z} >> block::kShift; ++bz) {
            for (std::uint64_t by = klo.y >> block::kShift;
                 by <= std::uint64_t{khi.y} >> block::kShift; ++by) {
              for (std::uint64_t bx = klo.x >> block::kShift;
                   bx <= std::uint64_t{khi.x} >> block::kShift; ++bx) {
                pairs[out++] = {ranks.rank(bx, by, bz), static_cast<std::uint32_t>(i)};
              }
            }
          }
        }
      });
  // By block (the ranks' order is the block keys'), kernels in order within each (the pairs
  // were made in kernel order).
  radixSort(
      pairs, scratch_->pairs_other, std::max(1, ranks.bits()),
      [](const auto& pair) { return pair.first; }, scratch_->radix_counts);
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
  std::vector<BlockEntry*>& entries = scratch_->targets;
  entries.clear();
  const BlockRanks& ranks = scratch_->block_ranks;
  std::vector<std::uint64_t> block_keys;  // each group's block
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    if (p == 0 || pairs[p].first != pairs[p - 1].first) {
      starts.push_back(p);
      block_keys.push_back(ranks.blockKey(pairs[p].first));
      // Found or made here with its evidence (allocated by this thread, as a scan's other
      // blocks: from parallel tasks they would come from every worker's malloc arena), filled
      // in parallel below.
      BlockEntry& e = store_->entry(block_keys.back());
      (void)store_->evidence(e);
      entries.push_back(&e);
    }
  }
  starts.push_back(pairs.size());
  std::atomic<std::size_t> cell_updates{0};
  const SquaredKernelTable& table = squaredKernel();
  std::vector<block::BlockMask> reached(reached_blocks != nullptr ? starts.size() - 1 : 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, starts.size() - 1, 4),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::size_t updates = 0;
                      // A block's sums of this scan in double (in kernel order), added to its float
                      // evidence once the block is done.
                      std::array<double, block::kVoxels> sum_alpha{}, sum_beta{};
                      for (std::size_t g = range.begin(); g != range.end(); ++g) {
                        const std::uint64_t block_key = block_keys[g];
                        block::BlockMask summed{};
                        for (std::size_t p = starts[g]; p < starts[g + 1]; ++p) {
                          const Kernel& k = kernels[pairs[p].second];
                          const bool point = !k.cell && k.inverse_length != 0.0 && k.to == k.x;
                          const VoxelKey& klo = k.key_min;
                          const VoxelKey& khi = k.key_max;
                          const VoxelKey base = block::keyOf(block_key, 0);
                          const auto range_of = [&](int axis, std::uint16_t from,
                                                    std::uint16_t to) {
                            const int b0 = base[axis];
                            return std::pair<int, int>(std::max<int>(from, b0),
                                                       std::min<int>(to, b0 + block::kEdge - 1));
                          };
                          const auto [x0, x1] = range_of(0, klo.x, khi.x);
                          const auto [y0, y1] = range_of(1, klo.y, khi.y);
                          const auto [z0, z1] = range_of(2, klo.z, khi.z);
                          if (k.stencil >= 0 && !options_.whole_boxes) {
                            accumulateStencilKernel(*scratch_->hit_stencils, k, x0, x1, y0, y1, z0,
                                                    z1, sum_alpha, summed, updates);
                            continue;
                          }
                          if (point && !options_.whole_boxes) {
                            accumulatePointKernel(grid_, k, x0, x1, y0, y1, z0, z1, table,
                                                  sum_alpha, sum_beta, summed, updates);
                            continue;
                          }
                          accumulateKernel(grid_, options_, k, point, x0, x1, y0, y1, z0, z1, table,
                                           sum_alpha, sum_beta, summed, updates);
                        }
                        BlockEvidence& b = *entries[g]->evidence;
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
  // Blocks a kernel's box overlaps but none of whose cells it reaches hold no evidence: made
  // above, dropped here (the published map never hears of them, so eviction would never drop
  // them, and they would pile up on a long drive).
  for (BlockEntry* e : entries) {
    if (!block::anyBit(e->evidence->known)) store_->dropEvidence(*e);
  }
  if (reached_blocks != nullptr) {
    for (std::size_t g = 0; g + 1 < starts.size(); ++g) {
      // A block no cell of which was reached is not the published map's business either.
      if (block::countBits(reached[g]) != 0) {
        reached_blocks->emplace_back(block_keys[g], reached[g]);
      }
    }
  }
  scratch_->releaseKernels();
  return cell_updates.load();
}

/// Adds the free traversal's sums to the blocks' beta; appends the blocks it reached to
/// `reached` when given.
void KernelMap::applyFree(std::vector<std::pair<std::uint64_t, block::BlockMask>>* reached_blocks) {
  // The blocks found (or made) one by one, then filled in parallel: one block per task.
  const std::vector<const FreeTraversal::Block*>& free_blocks = free_->blocks();
  std::vector<BlockEntry*>& targets = scratch_->targets;
  targets.resize(free_blocks.size());
  const double inverse_scale = 1.0 / free_->scale();
  for (std::size_t i = 0; i < free_blocks.size(); ++i) {
    targets[i] = &store_->entry(free_blocks[i]->key);
    (void)store_->evidence(*targets[i]);  // allocated here, by this thread (see above)
    if (reached_blocks != nullptr)
      reached_blocks->emplace_back(free_blocks[i]->key, free_blocks[i]->mask);
  }
  tbb::parallel_for(std::size_t{0}, free_blocks.size(), [&](std::size_t i) {
    BlockEvidence& b = *targets[i]->evidence;
    FreeTraversal::addEvidence(*free_blocks[i], inverse_scale, b.beta, b.known);
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

}  // namespace densemap::kernel
