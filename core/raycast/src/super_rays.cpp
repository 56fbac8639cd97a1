#include "densemap/raycast/super_rays.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

namespace densemap {
namespace {

constexpr double kSlopeMargin = 1e-9;     // relative; the traversal's double error is ~1e-12
constexpr double kEndMarginPerM = 1e-5;   // x ray length; float direction error is ~3e-7
constexpr double kEndMarginCells = 1e-6;  // x resolution; the float half step is ~3e-8
constexpr double kSlopeWiden = 1e-6;      // slopes just outside the rays' range still count

// Sort keys: (occupied flag, end voxel relative to the sensor's, 13 bits per axis) in the top
// 40 bits, the ray's index in the low 24. Rays ending farther than 4095 voxels away (or out of
// range) get the all-ones cell code and pass through.
constexpr int kIndexBits = 24;
constexpr std::uint64_t kNoCell = (std::uint64_t{1} << 40) - 1;
constexpr int kRelativeBits = 13;
constexpr int kRelativeMax = (1 << (kRelativeBits - 1)) - 1;

std::uint64_t cellCode(const RayEnd& r, const VoxelKey& origin) {
  if (!r.key_valid) return kNoCell;
  std::uint64_t code = r.occupied ? 1 : 0;
  for (int a = 0; a < 3; ++a) {
    const int d = static_cast<int>(r.key[a]) - static_cast<int>(origin[a]);
    if (d < -kRelativeMax || d > kRelativeMax) return kNoCell;
    code = (code << kRelativeBits) | static_cast<std::uint64_t>(d + kRelativeMax);
  }
  return code;
}

/// LSD radix sort of the top 40 bits (3 passes of 14, 13 and 13 bits: measured faster than 5
/// of 8); `tmp` and `count` are scratch.
void radixSort(std::vector<std::uint64_t>& v, std::vector<std::uint64_t>& tmp,
               std::vector<std::uint32_t>& count) {
  tmp.resize(v.size());
  int shift = kIndexBits;
  for (const int bits : {14, 13, 13}) {
    const std::uint64_t mask = (std::uint64_t{1} << bits) - 1;
    count.assign((std::size_t{1} << bits) + 1, 0);
    for (const std::uint64_t x : v) ++count[((x >> shift) & mask) + 1];
    for (std::size_t b = 0; b + 1 < count.size(); ++b) count[b + 1] += count[b];
    for (const std::uint64_t x : v) tmp[count[(x >> shift) & mask]++] = x;
    v.swap(tmp);
    shift += bits;
  }
}

/// Appends the critical slopes D_b(m) / D_a(n) in [lo, hi] for 0 <= n <= na, 0 <= m <= nb,
/// where D_a(n) = da0 + n * res; only pairs with D_a and D_b of the same strict sign (other
/// pairs are ordered the same way for every ray). Walks the axis with fewer crossings.
void criticalSlopes(double da0, int na, double db0, int nb, double res, double lo, double hi,
                    std::vector<double>& out) {
  const auto add = [&](double da, double db) {
    if ((da > 0 && db > 0) || (da < 0 && db < 0)) {
      const double s = db / da;
      if (s >= lo && s <= hi) out.push_back(s);
    }
  };
  const auto clampIndex = [](double v, int n) {
    if (!(v > 0)) return 0;
    if (v > n) return n;
    return static_cast<int>(v);
  };
  // Negative distances only happen for the first border (sensor a hair past it).
  if (da0 < 0 && db0 < 0) add(da0, db0);
  if (na <= nb) {
    for (int n = 0; n <= na; ++n) {
      const double da = da0 + n * res;
      if (!(da > 0)) continue;
      const int m0 = clampIndex(std::ceil((lo * da - db0) / res) - 1, nb);
      const int m1 = clampIndex(std::floor((hi * da - db0) / res) + 1, nb);
      for (int m = m0; m <= m1; ++m) add(da, db0 + m * res);
    }
  } else {
    for (int m = 0; m <= nb; ++m) {
      const double db = db0 + m * res;
      if (!(db > 0)) continue;
      const int n0 = clampIndex(std::ceil((db / hi - da0) / res) - 1, na);
      const int n1 = clampIndex(std::floor((db / lo - da0) / res) + 1, na);
      for (int n = n0; n <= n1; ++n) add(da0 + n * res, db);
    }
  }
}

/// How many of the sorted `values` are below `v` (std::lower_bound's index): a branch-free
/// count for short lists (a cell's critical slopes mostly are), a binary search otherwise.
std::size_t countBelow(const std::vector<double>& values, double v) {
  if (values.size() > 64) {
    return static_cast<std::size_t>(std::lower_bound(values.begin(), values.end(), v) -
                                    values.begin());
  }
  std::size_t count = 0;
  for (const double x : values) count += x < v ? 1 : 0;
  return count;
}

}  // namespace

std::size_t SuperRayBuilder::groupCell(const VoxelGrid& grid, const Point3f& origin,
                                       std::span<const RayEnd> rays, RayEnd* out,
                                       Scratch& scratch) {
  const VoxelKey end_key = rays[0].key;
  const auto origin_key = grid.pointToKey(origin);
  if (!origin_key || *origin_key == end_key) {
    // No traversal at all (traverseRay visits nothing): one ray carries the whole weight.
    out[0] = rays[0];
    out[0].weight = 0;
    for (const RayEnd& r : rays) out[0].weight += r.weight;
    return 1;
  }
  describeRays(grid, origin, end_key, rays, scratch);
  classifySlopes(grid, origin, *origin_key, end_key, scratch);
  return emitGroups(rays, out, scratch);
}

/// Each ray's direction exactly as traverseRay computes it, its step class (the signs of its
/// steps), and whether its end lies clear of the end voxel's faces (scratch.info).
void SuperRayBuilder::describeRays(const VoxelGrid& grid, const Point3f& origin,
                                   const VoxelKey& end_key, std::span<const RayEnd> rays,
                                   Scratch& scratch) {
  const std::size_t n = rays.size();
  const double res = grid.resolution();
  const double factor = grid.resolutionFactor();

  auto& info = scratch.info;
  info.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point3f& e = rays[i].end;
    auto& ri = info[i];
    float dir[3] = {e.x() - origin.x(), e.y() - origin.y(), e.z() - origin.z()};
    const float norm_sq = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
    const float length = static_cast<float>(std::sqrt(static_cast<double>(norm_sq)));
    ri.step_class = 0;
    for (int a = 0; a < 3; ++a) {
      ri.dir[a] = dir[a] / length;
      ri.step_class = ri.step_class * 3 + (ri.dir[a] > 0.0F ? 2U : ri.dir[a] < 0.0F ? 0U : 1U);
      ri.segment[a] = 0;
    }
    const double margin = (kEndMarginPerM * length + kEndMarginCells * res) * factor;
    ri.certain = true;
    for (int a = 0; a < 3; ++a) {
      const double u = static_cast<double>(e[a]) * factor -
                       (static_cast<double>(end_key[a]) - VoxelGrid::kMaxKey);
      if (!(u >= margin && u <= 1.0 - margin)) ri.certain = false;
    }
  }
}

/// Per step class, the segment of each pair of axes' slope between the critical slopes where
/// the traversal's order of border crossings changes (scratch.info[].segment); a ray near a
/// critical slope is not certain. Rays of one class and segments cross the same cells.
void SuperRayBuilder::classifySlopes(const VoxelGrid& grid, const Point3f& origin,
                                     const VoxelKey& origin_key, const VoxelKey& end_key,
                                     Scratch& scratch) {
  auto& info = scratch.info;
  const std::size_t n = info.size();
  const double res = grid.resolution();
  // Rays with equal step signs share the traversal's borders; classify them per class.
  auto& order = scratch.order;
  order.resize(n);
  bool one_class = true;
  for (std::size_t i = 0; i < n; ++i) {
    order[i] = static_cast<std::uint32_t>(i);
    one_class = one_class && info[i].step_class == info[0].step_class;
  }
  if (!one_class) {  // (usually all rays of a cell step the same way)
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
      return info[a].step_class != info[b].step_class ? info[a].step_class < info[b].step_class
                                                      : a < b;
    });
  }
  constexpr int kPairs[3][2] = {{0, 1}, {1, 2}, {0, 2}};
  for (std::size_t begin = 0; begin < n;) {
    std::size_t end = begin;
    while (end < n && info[order[end]].step_class == info[order[begin]].step_class) ++end;
    const auto& first = info[order[begin]];
    int step[3];
    double d0[3];
    int crossings[3];
    for (int a = 0; a < 3; ++a) {
      step[a] = first.dir[a] > 0.0F ? 1 : (first.dir[a] < 0.0F ? -1 : 0);
      crossings[a] = std::abs(static_cast<int>(end_key[a]) - static_cast<int>(origin_key[a]));
      d0[a] = 0;
      if (step[a] != 0) {
        // traverseRay's first border, with its float half step.
        double border = grid.keyToCoord(origin_key[a]);
        border += static_cast<float>(step[a] * res * 0.5);
        d0[a] = step[a] * (border - static_cast<double>(origin[a]));
      }
    }
    for (int p = 0; p < 3; ++p) {
      const int a = kPairs[p][0], b = kPairs[p][1];
      if (step[a] == 0 || step[b] == 0) continue;  // a zero step is never taken: same for all
      const auto slope = [&](const Scratch::Info& ri) {
        return std::fabs(static_cast<double>(ri.dir[b])) /
               std::fabs(static_cast<double>(ri.dir[a]));
      };
      double lo = slope(first), hi = lo;
      for (std::size_t j = begin; j < end; ++j) {
        const double s = slope(info[order[j]]);
        lo = std::min(lo, s);
        hi = std::max(hi, s);
      }
      auto& slopes = scratch.slopes;
      slopes.clear();
      criticalSlopes(d0[a], crossings[a], d0[b], crossings[b], res, lo * (1.0 - kSlopeWiden),
                     hi * (1.0 + kSlopeWiden), slopes);
      std::sort(slopes.begin(), slopes.end());
      for (std::size_t j = begin; j < end; ++j) {
        auto& ri = info[order[j]];
        const double s = slope(ri);
        const auto it = slopes.begin() + static_cast<std::ptrdiff_t>(countBelow(slopes, s));
        ri.segment[p] = static_cast<std::uint32_t>(it - slopes.begin());
        const auto near = [&](double c) { return std::fabs(s - c) <= kSlopeMargin * (s + c); };
        if ((it != slopes.end() && near(*it)) || (it != slopes.begin() && near(*(it - 1)))) {
          ri.certain = false;
        }
      }
    }
    begin = end;
  }
}

/// Uncertain rays pass through as they are; the others form one super ray per (class,
/// segments), weighing their count, in ray order within each. Returns how many were written.
std::size_t SuperRayBuilder::emitGroups(std::span<const RayEnd> rays, RayEnd* out,
                                        Scratch& scratch) {
  const std::size_t n = rays.size();
  const auto& info = scratch.info;
  auto& order = scratch.order;
  // Uncertain rays pass through; the others form one super ray per (class, segments).
  std::size_t written = 0;
  std::size_t kept = 0;
  bool packable = true;  // every segment index fits 16 bits: groups sort as one integer
  for (std::size_t i = 0; i < n; ++i) {
    if (info[i].certain) {
      order[kept++] = static_cast<std::uint32_t>(i);
      const auto& seg = info[i].segment;
      packable = packable && (seg[0] | seg[1] | seg[2]) < (1U << 16);
    } else {
      out[written++] = rays[i];
    }
  }
  if (packable) {
    auto& keyed = scratch.keyed;
    keyed.resize(kept);
    for (std::size_t j = 0; j < kept; ++j) {
      const auto& x = info[order[j]];
      keyed[j] = {(std::uint64_t{x.step_class} << 48) | (std::uint64_t{x.segment[0]} << 32) |
                      (std::uint64_t{x.segment[1]} << 16) | x.segment[2],
                  order[j]};
    }
    std::sort(keyed.begin(), keyed.end());  // (group, ray index): the order of the sort below
    for (std::size_t j = 0; j < kept;) {
      std::size_t k = j;
      RayEnd group = rays[keyed[j].second];
      group.weight = 0;
      while (k < kept && keyed[k].first == keyed[j].first) {
        group.weight += rays[keyed[k++].second].weight;
      }
      out[written++] = group;
      j = k;
    }
    return written;
  }
  const auto same = [&](std::uint32_t a, std::uint32_t b) {
    const auto& x = info[a];
    const auto& y = info[b];
    return x.step_class == y.step_class && x.segment[0] == y.segment[0] &&
           x.segment[1] == y.segment[1] && x.segment[2] == y.segment[2];
  };
  std::sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(kept),
            [&](std::uint32_t a, std::uint32_t b) {
              const auto& x = info[a];
              const auto& y = info[b];
              if (x.step_class != y.step_class) return x.step_class < y.step_class;
              for (int p = 0; p < 3; ++p) {
                if (x.segment[p] != y.segment[p]) return x.segment[p] < y.segment[p];
              }
              return a < b;
            });
  for (std::size_t j = 0; j < kept;) {
    std::size_t k = j;
    RayEnd group = rays[order[j]];
    group.weight = 0;
    while (k < kept && same(order[j], order[k])) group.weight += rays[order[k++]].weight;
    out[written++] = group;
    j = k;
  }
  return written;
}

SuperRayStats SuperRayBuilder::build(const VoxelGrid& grid, const Point3f& origin,
                                     std::vector<RayEnd>& rays, std::size_t min_points) {
  SuperRayStats stats;
  const std::size_t n = rays.size();
  const auto origin_key = grid.pointToKey(origin);
  if (!origin_key || n >= (std::size_t{1} << kIndexBits)) {
    return stats;  // nothing to traverse, or too many rays to index: leave them alone
  }
  order_.resize(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        order_[i] = (cellCode(rays[i], *origin_key) << kIndexBits) | i;
                      }
                    });
  radixSort(order_, sort_tmp_, radix_count_);

  const auto cellOf = [](std::uint64_t x) { return x >> kIndexBits; };
  const auto indexOf = [](std::uint64_t x) {
    return static_cast<std::uint32_t>(x & ((std::uint64_t{1} << kIndexBits) - 1));
  };
  // The runs of end voxels with enough rays to group (at least min_points, and 2), and their
  // rays flagged; the others' rays stay where they are (gathering them in the sorted order, a
  // random read a ray, was most of this function's time while most rays pass through).
  const std::size_t min_run = std::max<std::size_t>(min_points, 2);
  runs_.clear();
  grouped_.assign(n, 0);
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i;
    while (j < n && cellOf(order_[j]) == cellOf(order_[i])) ++j;
    if (j - i >= min_run && cellOf(order_[i]) != kNoCell) {
      runs_.emplace_back(static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j));
      for (std::size_t k = i; k < j; ++k) grouped_[indexOf(order_[k])] = 1;
    }
    i = j;
  }

  // Each run writes at most its own length, at its own offset; appended afterwards.
  out_.resize(n);
  written_.assign(runs_.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, runs_.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      Scratch& scratch = scratch_.local();
                      for (std::size_t r = range.begin(); r != range.end(); ++r) {
                        const auto [first, last] = runs_[r];
                        const std::size_t size = last - first;
                        scratch.cell.resize(size);
                        for (std::size_t j = 0; j < size; ++j)
                          scratch.cell[j] = rays[indexOf(order_[first + j])];
                        written_[r] = static_cast<std::uint32_t>(
                            groupCell(grid, origin, scratch.cell, out_.data() + first, scratch));
                      }
                    });

  // The rays not grouped, in their order, then the groups' rays.
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (grouped_[i] == 0) rays[kept++] = rays[i];
  }
  rays.resize(kept);
  for (std::size_t r = 0; r < runs_.size(); ++r) {
    const RayEnd* out = out_.data() + runs_[r].first;
    for (std::uint32_t j = 0; j < written_[r]; ++j) {
      rays.push_back(out[j]);
      if (out[j].weight > 1) ++stats.super_rays;
    }
  }
  return stats;
}

}  // namespace densemap
