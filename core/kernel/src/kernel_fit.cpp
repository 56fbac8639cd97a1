#include "kernel_fit.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <array>
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

/// kAkimapRays with aggregate_hits: the adaptive kernels of a scan's hits (`hits`: indices of
/// the occupied samples) and each hit's ray stop. A voxel with at least `aggregate_min_hits`
/// hits gets one kernel at their mean, weighing their count, fitted to the neighbourhood
/// outside the voxel; its normal sets its rays' stops. Other voxels keep a kernel per hit (a
/// mean would lose the spread of a few hits, which is their shape: a grazing floor's), each
/// fitted alone, or, from `shared_fit_min_hits` hits, all of the shape fitted at their mean.
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
          Sample centre;
          centre.occupied = true;
          for (std::uint32_t p = first; p < last; ++p) {
            const Sample& h = samples[hits[by_voxel[p].second]];
            centre.x += h.x;
            centre.range += h.range;
          }
          const double count = n;
          centre.x /= count;
          centre.to = centre.x;
          centre.range /= count;
          // The voxel's own hits are not its neighbours: recognised by their group (they had
          // been by position, with the key's own test near the voxel's faces: a float-to-key
          // conversion per neighbour there).
          const auto own = static_cast<std::uint32_t>(g);
          Kernel k = adaptiveKernel(
              centre, [&](const SampleIndex::Entry& e) { return group_of[e.index] == own; }, index,
              options, grid.resolution(), neighbours, &normal);
          if (n < min_hits) {
            for (std::uint32_t p = first; p < last; ++p, ++out) {
              const std::uint32_t h = by_voxel[p].second, i = hits[h];
              kernels[out] = k;
              kernels[out].x = kernels[out].to = samples[i].x;
              means[out] = samples[i].x;
              counts[out] = 1.0;
              stops[h] = rayStop((samples[i].x - origin).normalized(), normal, options);
            }
            continue;
          }
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

}  // namespace densemap::kernel::detail
