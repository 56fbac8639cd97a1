#pragma once

#include <Eigen/Core>
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/kernel/bandwidth.hpp"
#include "densemap/kernel/kernel_function.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "sample_index.hpp"

/// The kernels a scan's samples give (AKIMap's adaptive kernels, BGK's isotropic ones,
/// akimap_rays' per-voxel kernels and ray stops): fitted here, accumulated by KernelMap.
namespace densemap::kernel::detail {

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
  /// A hit kernel read from HitStencils (>= 0: its sub-position; `stencil_key`: its voxel).
  std::int32_t stencil = -1;
  VoxelKey stencil_key;

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
};

/// A kernel's rows: the x interval [lo, hi] (m) of the row at (y, z) outside which the kernel is
/// 0: exact for ellipsoids, the infinite cylinder around a segment cut by its end planes (a
/// superset of the capsule) otherwise. False when the row misses the support. Widened by a
/// micrometre so that rounding never drops a cell the kernel reaches. The terms that do not
/// depend on the row are computed once, when made for a kernel (its rows were a call each,
/// each recomputing them: 5% of a 1-thread akimap_rays scan).
class RowIntervals {
 public:
  explicit RowIntervals(const Kernel& k) : k_(k) {
    if (k.cell) return;
    if (k.inverse_length == 0.0) {
      a_ = k.h_inverse(0, 0);
    } else {
      const Eigen::Vector3d seg = k.to - k.x;
      const double length2 = seg.squaredNorm();  // a point kernel (0) takes no square root
      r2_ = k.inverse_length * k.inverse_length;
      if (length2 > 0.0) {
        segment_ = true;
        length_ = std::sqrt(length2);  // seg.norm()
        u_ = seg / length_;
        a_ = (1.0 - u_.x() * u_.x()) * r2_;
        radius_ = 1.0 / k.inverse_length;
      } else {
        a_ = r2_;
      }
    }
    // One division: the product differs from the quotient by an ulp, far inside the slack, so
    // every cell the kernel reaches stays inside (and one let in lies outside its support).
    inverse_a_ = 1.0 / a_;
  }

  // Inlined into the accumulation's row loop (GCC would keep it a call, which costs the
  // accumulation about a tenth of its instructions).
  [[nodiscard]] [[gnu::always_inline]] bool operator()(double y, double z, double& lo,
                                                       double& hi) const {
    constexpr double kSlack = 1e-6;
    lo = -std::numeric_limits<double>::infinity();
    hi = std::numeric_limits<double>::infinity();
    if (k_.cell) return true;
    const double dy = y - k_.x.y(), dz = z - k_.x.z();
    // a t^2 + 2 b t + c < 1 for t = cx - x.x (ellipsoid, or cylinder scaled to radius 1).
    double b = 0.0, c = 0.0;
    if (k_.inverse_length == 0.0) {
      const Eigen::Matrix3d& m = k_.h_inverse;
      b = m(0, 1) * dy + m(0, 2) * dz;
      c = m(1, 1) * dy * dy + 2.0 * m(1, 2) * dy * dz + m(2, 2) * dz * dz;
    } else if (segment_) {
      const double along_yz = dy * u_.y() + dz * u_.z();
      b = -u_.x() * along_yz * r2_;
      c = (dy * dy + dz * dz - along_yz * along_yz) * r2_;
      // End planes: -radius <= t u.x + along_yz <= length + radius.
      if (std::abs(u_.x()) > 1e-12) {
        double t0 = (-radius_ - along_yz) / u_.x(), t1 = (length_ + radius_ - along_yz) / u_.x();
        if (t0 > t1) std::swap(t0, t1);
        lo = k_.x.x() + t0 - kSlack;
        hi = k_.x.x() + t1 + kSlack;
      } else if (along_yz < -radius_ || along_yz > length_ + radius_) {
        return false;
      }
    } else {
      c = (dy * dy + dz * dz) * r2_;
    }
    if (a_ <= 1e-12) return c < 1.0 + kSlack;  // the row runs along the axis
    const double disc = b * b - a_ * (c - 1.0);
    if (disc < 0.0) return false;
    const double root = std::sqrt(disc);
    lo = std::max(lo, k_.x.x() + (-b - root) * inverse_a_ - kSlack);
    hi = std::min(hi, k_.x.x() + (-b + root) * inverse_a_ + kSlack);
    return lo <= hi;
  }

 private:
  const Kernel& k_;
  bool segment_ = false;
  Eigen::Vector3d u_ = Eigen::Vector3d::Zero();  // a segment's direction
  double a_ = 0.0, inverse_a_ = 0.0, r2_ = 0.0, length_ = 0.0, radius_ = 0.0;
};

/// kAkimapRays' direct hit evidence tabled: a hit's isotropic kernel (support radius
/// `length_voxels` voxels, `kernel_weight` at its centre) plus `cell_weight` on the hit's own
/// cell, on the cells around its voxel, with the kernel's centre moved to the nearest of
/// `steps` + 1 sub-positions per axis across the voxel (i / steps of a voxel, 0 <= i <= steps,
/// faces included: a surface on a voxel face keeps its hits' kernels there; 1: the voxel's
/// corners). The value at offset o from the voxel is then kernel_weight *
/// table(|o + 0.5 - c|^2 / length^2) (+ cell_weight at o = 0) whatever the resolution: made
/// once, read per cell and scaled by the hits' count, instead of two kernels per hit evaluated
/// cell by cell (the hit kernels were 11% of a BALM scan at 0.2 m, 2 threads).
class HitStencils {
 public:
  /// Empty (usable() false) when steps is 0 or the tables would exceed `max_values`.
  HitStencils(double length_voxels, int steps, double kernel_weight, double cell_weight,
              const SquaredKernelTable& table, std::size_t max_values = std::size_t{1} << 18);
  [[nodiscard]] bool usable() const { return !values_.empty(); }
  /// Offsets from the kernel's voxel run over [-reach, reach] on each axis.
  [[nodiscard]] int reach() const { return reach_; }
  /// The sub-position nearest a point whose offsets inside its voxel are f (voxels, [0, 1]).
  [[nodiscard]] std::int32_t subPosition(const Eigen::Vector3d& f) const;
  /// The sub-position's centre inside its voxel (voxels).
  [[nodiscard]] Eigen::Vector3d centreOf(std::int32_t sub) const;
  /// The values of sub-position `sub`'s row at offsets (., dy, dz), indexed by dx + reach.
  [[nodiscard]] const double* row(std::int32_t sub, int dy, int dz) const {
    return values_.data() + rowIndex(sub, dy, dz) * width_;
  }
  /// The offsets dx of that row where the kernel is not 0 ([first, last]; first > last: none).
  [[nodiscard]] std::pair<int, int> rowExtent(std::int32_t sub, int dy, int dz) const {
    return extents_[rowIndex(sub, dy, dz)];
  }

 private:
  [[nodiscard]] std::size_t rowIndex(std::int32_t sub, int dy, int dz) const {
    return (static_cast<std::size_t>(sub) * width_ + static_cast<std::size_t>(dz + reach_)) *
               width_ +
           static_cast<std::size_t>(dy + reach_);
  }
  int steps_ = 0, reach_ = 0;
  std::size_t width_ = 0;
  std::vector<double> values_;
  std::vector<std::pair<int, int>> extents_;
};

/// The tables for these settings, made on first use and shared by every map of the process
/// (as squaredKernel(): they are constants, up to 2 MiB each); null after 64 distinct
/// settings (the caller then evaluates the kernels).
[[nodiscard]] const HitStencils* sharedHitStencils(double length_voxels, int steps,
                                                   double kernel_weight, double cell_weight);

/// BGK's isotropic kernel for sample s (its length scale: o.length_scale, tips
/// o.tip_length_scale).
[[nodiscard]] Kernel isotropicKernel(const Sample& s, const KernelOptions& o);

/// AKIMap's kernel for sample i (Sec. 3.3.3): covariance of same-label neighbours in the search
/// box, then the scale minimising Eq. 3.7.
/// When `normal` is given, it is set to the surface normal at the sample (the covariance's
/// least axis) where the same-label neighbourhood is flat (least spread under a quarter of
/// the middle one, regulariser aside), else to zero.
/// `s` is a sample or a voxel's mean hit; `left_out(entry)` says which samples are not its
/// neighbours (the sample itself, or the voxel's own hits).
template <class LeftOut>
Kernel adaptiveKernel(const Sample& s, LeftOut&& left_out, const SampleIndex& index,
                      const KernelOptions& o, double resolution, std::vector<Neighbour>& neighbours,
                      Eigen::Vector3d* normal = nullptr) {
  const double range_ref = o.max_range > 0.0 ? o.max_range : o.search_range;
  const double half =
      resolution + (o.search_max - resolution) * std::clamp(s.range / range_ref, 0.0, 1.0);
  const std::size_t found = index.neighboursInBox(
      s.x, half, s.occupied, [&](const SampleIndex::Entry& e) { return !left_out(e); }, neighbours);
  const std::span<const Neighbour> near(neighbours.data(), found);
  // The regulariser keeps flat kernels at least `min_thickness` (and a voxel) thick, one
  // standard deviation, so a surface's samples reach the centres of the cells they lie in; the
  // isotropic fallback spans half the search box.
  const double thickness = std::max(o.min_thickness, resolution);
  const double regulariser = thickness * thickness;
  const Eigen::Matrix3d sigma = neighbourCovariance(s.x, near, regulariser, 0.25 * half * half);
  // The closed form for 3 x 3 (Eigen's computeDirect; the iterative QR took a quarter of a
  // BALM kernel's fit): the same maps on every accuracy row to the digits printed, not bit for
  // bit. Its eigenvectors of a well-separated least eigenvalue (the only ones used, as normals)
  // are accurate; a normal's sign does not matter (rayStop takes |cos|).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen;
  eigen.computeDirect(sigma,
                      normal != nullptr ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
  const double largest = eigen.eigenvalues().maxCoeff();  // ascending: [0] least, [2] largest
  if (normal != nullptr) {
    const std::size_t same = static_cast<std::size_t>(
        std::count_if(near.begin(), near.end(), [](const Neighbour& n) { return n.same_label; }));
    const double least = eigen.eigenvalues()[0] - regulariser;
    const double middle = eigen.eigenvalues()[1] - regulariser;
    *normal = same >= 3 && middle > 4.0 * std::max(least, 0.0) && middle > 0.0
                  ? Eigen::Vector3d(eigen.eigenvectors().col(0))
                  : Eigen::Vector3d::Zero();
  }
  // The support (sqrt(s * lambda) along each axis) stays inside the search box.
  const double s_max = std::max(1.0, half * half / largest);
  const double scale = fitScale(sigma, s.x, near, 1.0 / 16.0, s_max);
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
[[nodiscard]] std::vector<Eigen::Vector3d> hitsOf(const PointCloud& points_world,
                                                  const Eigen::Vector3d& origin, double max_range);
/// Where kAkimapRays' free evidence along a ray stops (see kernel_fit.cpp).
[[nodiscard]] RayStop rayStop(const Eigen::Vector3d& ray, const Eigen::Vector3d& normal,
                              const KernelOptions& o);
/// kAkimapRays' direct hit evidence (see kernel_fit.cpp); the hit kernels from `stencils` when
/// given and usable.
void appendHitKernels(const std::vector<Eigen::Vector3d>& positions,
                      const std::vector<double>* counts, const KernelOptions& o,
                      const VoxelGrid& grid, const HitStencils* stencils,
                      std::vector<Kernel>& kernels);
/// kAkimapRays' kernels of the hits voxel by voxel (see kernel_fit.cpp).
void adaptiveVoxelKernels(const VoxelGrid& grid, const KernelOptions& options,
                          const std::vector<Sample>& samples,
                          const std::vector<std::uint32_t>& hits, const SampleIndex& index,
                          const Eigen::Vector3d& origin, std::vector<Kernel>& kernels,
                          std::vector<RayStop>& stops, std::vector<Eigen::Vector3d>& means,
                          std::vector<double>& counts);

}  // namespace densemap::kernel::detail
