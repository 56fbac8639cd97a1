#include "kernel_fit.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <array>
#include <cmath>
#include <deque>
#include <mutex>
#include <optional>
#include <unordered_map>

namespace densemap::kernel::detail {

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

HitStencils::HitStencils(double length_voxels, int steps, double kernel_weight, double cell_weight,
                         const SquaredKernelTable& table, std::size_t max_values) {
  if (steps <= 0 || !(length_voxels > 0.0) || length_voxels > 64.0) return;
  // A centre in its voxel (faces included) reaches the cells within length_voxels of it:
  // offsets up to ceil(length) + 1 on each side.
  reach_ = static_cast<int>(std::ceil(length_voxels)) + 1;
  width_ = static_cast<std::size_t>(2 * reach_ + 1);
  const auto subs = static_cast<std::size_t>(steps + 1) * (steps + 1) * (steps + 1);
  if (subs * width_ * width_ * width_ > max_values) return;
  steps_ = steps;
  values_.assign(subs * width_ * width_ * width_, 0.0);
  extents_.assign(subs * width_ * width_, {1, 0});
  const double inverse_length2 = 1.0 / (length_voxels * length_voxels);
  for (std::int32_t sub = 0; sub < static_cast<std::int32_t>(subs); ++sub) {
    const Eigen::Vector3d c = centreOf(sub);
    for (int dz = -reach_; dz <= reach_; ++dz) {
      for (int dy = -reach_; dy <= reach_; ++dy) {
        double* const values = values_.data() + rowIndex(sub, dy, dz) * width_;
        std::pair<int, int>& extent = extents_[rowIndex(sub, dy, dz)];
        extent = {reach_ + 1, -reach_ - 1};
        for (int dx = -reach_; dx <= reach_; ++dx) {
          const Eigen::Vector3d d = Eigen::Vector3d(dx + 0.5, dy + 0.5, dz + 0.5) - c;
          const double v = kernel_weight * table(d.squaredNorm() * inverse_length2) +
                           (dx == 0 && dy == 0 && dz == 0 ? cell_weight : 0.0);
          values[dx + reach_] = v;
          if (v > 0.0) extent = {std::min(extent.first, dx), std::max(extent.second, dx)};
        }
      }
    }
  }
}

const HitStencils* sharedHitStencils(double length_voxels, int steps, double kernel_weight,
                                     double cell_weight) {
  static std::mutex mutex;
  static std::deque<std::pair<std::array<double, 4>, HitStencils>> made;  // never moved
  const std::array<double, 4> key{length_voxels, static_cast<double>(steps), kernel_weight,
                                  cell_weight};
  const std::lock_guard lock(mutex);
  for (const auto& [settings, stencils] : made) {
    if (settings == key) return &stencils;
  }
  if (made.size() >= 64) return nullptr;
  made.emplace_back(key,
                    HitStencils(length_voxels, steps, kernel_weight, cell_weight, squaredKernel()));
  return &made.back().second;
}

std::int32_t HitStencils::subPosition(const Eigen::Vector3d& f) const {
  std::int32_t sub = 0;
  for (int a = 2; a >= 0; --a) {
    const int i = std::clamp(static_cast<int>(std::lround(f[a] * steps_)), 0, steps_);
    sub = sub * (steps_ + 1) + i;
  }
  return sub;
}

Eigen::Vector3d HitStencils::centreOf(std::int32_t sub) const {
  Eigen::Vector3d c;
  for (int a = 0; a < 3; ++a) {
    c[a] = static_cast<double>(sub % (steps_ + 1)) / steps_;
    sub /= steps_ + 1;
  }
  return c;
}

/// kAkimapRays' direct hit evidence: per hit, its cell (hit_weight) and an isotropic kernel of
/// hit_length_voxels (hit_kernel_weight); with `counts`, `positions` are voxels' mean hits, each
/// standing for that many hits (the cell's evidence is then exactly the hits' sum). With
/// usable `stencils`, one tabled kernel holds both, weighing the hits' count; consecutive
/// positions in the same voxel and sub-position share one. Each position's voxel, centre and
/// sub-position are found in parallel; the kernels are then made in order.
void appendHitKernels(const std::vector<Eigen::Vector3d>& positions,
                      const std::vector<double>* counts, const KernelOptions& o,
                      const VoxelGrid& grid, const HitStencils* stencils,
                      std::vector<Kernel>& kernels) {
  const double resolution = grid.resolution();
  const double radius = o.hit_length_voxels * resolution;
  const bool tabled = stencils != nullptr && stencils->usable();
  const bool keyed = tabled || o.hit_centre_pull > 0.0;
  // Per position: its voxel (keyed only), its kernel's centre and, tabled, its sub-position.
  struct Place {
    std::optional<VoxelKey> key;
    std::int32_t sub = -1;
    Eigen::Vector3d centre;
  };
  std::vector<Place> places(positions.size());
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, positions.size(), 4096),
      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          Place& place = places[i];
          place.key = keyed ? grid.pointToKey(positions[i].cast<float>()) : std::nullopt;
          // The hit kernel's centre (hit_centre_pull of the way to the voxel's centre).
          place.centre = positions[i];
          if (place.key && o.hit_centre_pull > 0.0) {
            const VoxelKey& key = *place.key;
            const Eigen::Vector3d voxel_centre(grid.keyToCoord(key.x), grid.keyToCoord(key.y),
                                               grid.keyToCoord(key.z));
            place.centre += o.hit_centre_pull * (voxel_centre - place.centre);
          }
          if (place.key && tabled) {
            // The voxel's lower corner, then the centre's offsets inside it (voxels).
            Eigen::Vector3d corner;
            for (int a = 0; a < 3; ++a) {
              corner[a] = grid.keyToCoord((*place.key)[a]) - 0.5 * resolution;
            }
            place.sub = stencils->subPosition((place.centre - corner) / resolution);
            place.centre = corner + stencils->centreOf(place.sub) * resolution;
          }
        }
      });
  std::size_t last_tabled = kernels.size();  // none yet
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const double count = counts != nullptr ? (*counts)[i] : 1.0;
    const Place& place = places[i];
    Kernel k;
    k.x = k.to = positions[i];
    k.occupied = true;
    if (place.sub >= 0) {
      if (last_tabled < kernels.size() && kernels[last_tabled].stencil_key == *place.key &&
          kernels[last_tabled].stencil == place.sub) {
        kernels[last_tabled].weight += count;
        continue;
      }
      k.stencil = place.sub;
      k.stencil_key = *place.key;
      k.x = k.to = place.centre;
      k.weight = count;
      // The box the pairs are made from: the kernel's support around its centre (the cell is
      // inside it).
      k.half_extent.setConstant(radius);
      k.inverse_length = 1.0 / radius;
      last_tabled = kernels.size();
      kernels.push_back(k);
      continue;
    }
    if (o.hit_weight > 0.0) {
      k.weight = o.hit_weight * count;
      k.cell = true;
      k.half_extent.setZero();
      kernels.push_back(k);
    }
    if (o.hit_kernel_weight > 0.0) {
      k.weight = o.hit_kernel_weight * count;
      k.x = k.to = place.centre;
      k.cell = false;
      k.half_extent.setConstant(radius);
      k.inverse_length = 1.0 / radius;
      kernels.push_back(k);
    }
  }
}

/// Fits shared by cubes of `cube_voxels` voxels a side (KernelOptions::fit_cube_m): in each
/// cube the group of the most hits (`hitsIn(g)`; the first in group order among equals, so the
/// same whatever the thread count) is fitted, `fit(g, neighbours, normal)`, and every group of
/// the cube gets that fit and normal, `emit(g, fit, normal)`. A cube's fullest voxel has the
/// best-sampled neighbourhood. `position(g)`: one of the group's hits. A group outside the
/// addressable range keeps a fit of its own.
template <class Position, class HitsIn, class Fit, class Emit>
void shareFitsByCube(const VoxelGrid& grid, int cube_voxels, std::size_t groups,
                     const Position& position, const HitsIn& hitsIn, const Fit& fit,
                     const Emit& emit) {
  constexpr std::uint64_t kNone = ~std::uint64_t{0};
  std::vector<std::uint64_t> cube_of(groups);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t g = range.begin(); g != range.end(); ++g) {
                        const auto key = grid.pointToKey(position(g).template cast<float>());
                        cube_of[g] = !key ? kNone
                                          : (std::uint64_t(key->x / cube_voxels) << 32) |
                                                (std::uint64_t(key->y / cube_voxels) << 16) |
                                                std::uint64_t(key->z / cube_voxels);
                      }
                    });
  // Cube -> its fullest group (open addressing, at most half full), then each group's fitter.
  std::size_t slots = 1024;
  while (slots < 2 * groups) slots *= 2;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> table(slots, {kNone, 0});
  const auto slotOf = [&](std::uint64_t cube) {
    std::size_t i = static_cast<std::size_t>((cube * 0x9E3779B97F4A7C15ULL) >> 20) & (slots - 1);
    while (table[i].first != kNone && table[i].first != cube) i = (i + 1) & (slots - 1);
    return i;
  };
  for (std::size_t g = 0; g < groups; ++g) {
    if (cube_of[g] == kNone) continue;
    auto& [cube, fullest] = table[slotOf(cube_of[g])];
    if (cube == kNone) {
      cube = cube_of[g];
      fullest = static_cast<std::uint32_t>(g);
    } else if (hitsIn(g) > hitsIn(fullest)) {
      fullest = static_cast<std::uint32_t>(g);
    }
  }
  // Each group's fitter, and the fitters' fits in a slot each (on 64-beam scans a fifth of the
  // groups at 0.1 m, two fifths at 0.2 m: a fit is a whole kernel).
  std::vector<std::uint32_t> fitter(groups), slot_of(groups);
  std::uint32_t fitters = 0;
  for (std::size_t g = 0; g < groups; ++g) {
    fitter[g] =
        cube_of[g] == kNone ? static_cast<std::uint32_t>(g) : table[slotOf(cube_of[g])].second;
    if (fitter[g] == g) slot_of[g] = fitters++;
  }
  std::vector<std::uint64_t>().swap(cube_of);
  std::vector<std::pair<std::uint64_t, std::uint32_t>>().swap(table);
  std::vector<Kernel> fits(fitters);
  std::vector<Eigen::Vector3d> normals(fitters);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::vector<Neighbour> neighbours;
                      for (std::size_t g = range.begin(); g != range.end(); ++g) {
                        if (fitter[g] != g) continue;
                        const std::uint32_t slot = slot_of[g];
                        fits[slot] = fit(g, neighbours, normals[slot]);
                      }
                    });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 256),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t g = range.begin(); g != range.end(); ++g) {
                        const std::uint32_t slot = slot_of[fitter[g]];
                        emit(g, fits[slot], normals[slot]);
                      }
                    });
}

/// kAkimapRays with aggregate_hits: the adaptive kernels of a scan's hits (`hits`: indices of
/// the occupied samples) and each hit's ray stop. A voxel with at least `aggregate_min_hits`
/// hits gets one kernel at their mean, weighing their count, fitted to the neighbourhood
/// outside the voxel; its normal sets its rays' stops. Other voxels keep a kernel per hit (a
/// mean would lose the spread of a few hits, which is their shape: a grazing floor's), each
/// fitted alone, or, from `shared_fit_min_hits` hits, all of the shape fitted at their mean.
/// With `fit_cube_m`, the voxels of a cube share its fullest voxel's fit (shareFitsByCube).
/// `means` and `counts`: where the direct hit evidence goes and how many hits it stands for.
void adaptiveVoxelKernels(const VoxelGrid& grid, const KernelOptions& options,
                          const std::vector<Sample>& samples,
                          const std::vector<std::uint32_t>& hits, const SampleIndex& index,
                          const Eigen::Vector3d& origin, std::vector<Kernel>& kernels,
                          std::vector<RayStop>& stops, std::vector<Eigen::Vector3d>& means,
                          std::vector<double>& counts) {
  // By voxel (outside the addressable range: none, sorted last), hits in order within each;
  // the voxels ranked in the window of the max range around the origin.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> by_voxel, by_voxel_other;
  std::vector<std::uint32_t> radix_counts;
  sortByVoxel(
      hits.size(), [&](std::size_t h) { return grid.pointToKey(samples[hits[h]].x.cast<float>()); },
      KeyWindow::around(grid, origin, options.max_range), by_voxel, by_voxel_other, radix_counts);
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
  // Each hit's group (other samples: none), read by the parallel fits below.
  std::vector<std::uint32_t> group_of(samples.size(), ~std::uint32_t{0});
  for (std::size_t g = 0; g < groups; ++g) {
    for (std::uint32_t p = group_starts[g]; p < group_starts[g + 1]; ++p) {
      group_of[hits[by_voxel[p].second]] = static_cast<std::uint32_t>(g);
    }
  }
  // The fit at group g's mean hit, fitted to the neighbourhood outside its voxel (its own hits
  // recognised by their group, not by position: a float-to-key conversion per neighbour near
  // the voxel's faces), and its normal.
  const auto fitAtMean = [&](std::size_t g, std::vector<Neighbour>& neighbours,
                             Eigen::Vector3d& normal) {
    const std::uint32_t first = group_starts[g], last = group_starts[g + 1];
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
    const auto own = static_cast<std::uint32_t>(g);
    return adaptiveKernel(
        centre, [&](const SampleIndex::Entry& e) { return group_of[e.index] == own; }, index,
        options, grid.resolution(), neighbours, &normal);
  };
  // Group g's kernels from the fit `k` and its normal: one kernel at the hits' mean (as
  // fitAtMean sums it) weighing their count, or (fewer than min_hits) a kernel of that shape
  // per hit.
  const auto emit = [&](std::size_t g, Kernel k, const Eigen::Vector3d& normal) {
    const std::uint32_t first = group_starts[g], last = group_starts[g + 1];
    std::uint32_t out = outputs[g];
    const std::uint32_t n = last - first;
    if (n < min_hits) {
      for (std::uint32_t p = first; p < last; ++p, ++out) {
        const std::uint32_t h = by_voxel[p].second, i = hits[h];
        kernels[out] = k;
        kernels[out].x = kernels[out].to = samples[i].x;
        means[out] = samples[i].x;
        counts[out] = 1.0;
        stops[h] = rayStop((samples[i].x - origin).normalized(), normal, options);
      }
      return;
    }
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::uint32_t p = first; p < last; ++p) mean += samples[hits[by_voxel[p].second]].x;
    mean /= static_cast<double>(n);
    k.x = k.to = mean;
    k.weight *= n;
    kernels[out] = k;
    means[out] = mean;
    counts[out] = n;
    for (std::uint32_t p = first; p < last; ++p) {
      const std::uint32_t h = by_voxel[p].second;
      stops[h] = rayStop((samples[hits[h]].x - origin).normalized(), normal, options);
    }
  };
  const int cube_voxels =
      options.fit_cube_m > 0.0
          ? static_cast<int>(std::floor(options.fit_cube_m / grid.resolution() + 1e-9))
          : 1;
  if (cube_voxels >= 2) {
    shareFitsByCube(
        grid, cube_voxels, groups,
        [&](std::size_t g) { return samples[hits[by_voxel[group_starts[g]].second]].x; },
        [&](std::size_t g) { return group_starts[g + 1] - group_starts[g]; }, fitAtMean, emit);
    return;
  }
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, groups, 64),
      [&](const tbb::blocked_range<std::size_t>& range) {
        std::vector<Neighbour> neighbours;
        Eigen::Vector3d normal;
        for (std::size_t g = range.begin(); g != range.end(); ++g) {
          const std::uint32_t first = group_starts[g], last = group_starts[g + 1];
          std::uint32_t out = outputs[g];
          const std::uint32_t n = last - first;
          const bool shared = options.shared_fit_min_hits > 0.0 && n >= options.shared_fit_min_hits;
          if (n < min_hits && !shared) {  // a kernel per hit, as without aggregation
            for (std::uint32_t p = first; p < last; ++p, ++out) {
              const std::uint32_t h = by_voxel[p].second, i = hits[h];
              kernels[out] = adaptiveKernel(
                  samples[i], [i](const SampleIndex::Entry& e) { return e.index == i; }, index,
                  options, grid.resolution(), neighbours, &normal);
              means[out] = samples[i].x;
              counts[out] = 1.0;
              stops[h] = rayStop((samples[i].x - origin).normalized(), normal, options);
            }
            continue;
          }
          // One fit at the hits' mean: one kernel weighing their count, or (fewer than
          // min_hits, shared) a kernel per hit of that shape.
          const Kernel k = fitAtMean(g, neighbours, normal);
          emit(g, k, normal);
        }
      });
}

}  // namespace densemap::kernel::detail
