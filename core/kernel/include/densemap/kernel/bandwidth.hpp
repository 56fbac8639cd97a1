#pragma once

#include <Eigen/Core>
#include <span>

namespace densemap::kernel {

/// A sample near the kernel centre, and whether it has the centre's label (a "positive"
/// neighbour, dissertation Sec. 3.3.3) or not ("negative").
struct Neighbour {
  Eigen::Vector3d x;
  bool same_label = true;
};

/// Sigma_i of AKIMap: the covariance of the centre and its positive neighbours (about their
/// mean), plus `regulariser` * I so it stays positive definite (samples on a plane or a line
/// have a singular covariance). With fewer than 3 positive neighbours the shape is unknown:
/// `fallback_variance` * I (isotropic).
[[nodiscard]] Eigen::Matrix3d neighbourCovariance(const Eigen::Vector3d& centre,
                                                  std::span<const Neighbour> neighbours,
                                                  double regulariser, double fallback_variance);

/// Eq. 3.7's objective for scale s: |s Sigma|^(-1/2) / 2 * sum_j (t_j - k(x_j; s Sigma))^2,
/// with t_j = k(x_j; Sigma) for positive neighbours and 0 for negative ones (Eq. 3.6).
[[nodiscard]] double scaleObjective(double s, const Eigen::Matrix3d& sigma,
                                    const Eigen::Vector3d& centre,
                                    std::span<const Neighbour> neighbours);

/// The scale s_hat minimising Eq. 3.7, found as the paper does by descent from the covariance
/// itself (s = 1): a downhill walk on a log grid (8 steps per doubling) in [s_min, s_max], then
/// a golden-section refinement. The descent matters: the objective also tends to 0 as
/// s -> infinity (the weight |s Sigma|^(-1/2) vanishes), which is not the minimum meant.
[[nodiscard]] double fitScale(const Eigen::Matrix3d& sigma, const Eigen::Vector3d& centre,
                              std::span<const Neighbour> neighbours, double s_min, double s_max);

}  // namespace densemap::kernel
