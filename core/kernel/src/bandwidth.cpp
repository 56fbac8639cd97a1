#include "densemap/kernel/bandwidth.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "densemap/kernel/kernel_function.hpp"

namespace densemap::kernel {

Eigen::Matrix3d neighbourCovariance(const Eigen::Vector3d& centre,
                                    std::span<const Neighbour> neighbours, double regulariser,
                                    double fallback_variance) {
  Eigen::Vector3d sum = centre;
  int count = 1;
  for (const Neighbour& n : neighbours) {
    if (!n.same_label) continue;
    sum += n.x;
    ++count;
  }
  if (count < 4) return fallback_variance * Eigen::Matrix3d::Identity();
  const Eigen::Vector3d mean = sum / count;
  // The six distinct entries, summed in neighbour order (d_i d_j and d_j d_i are the same
  // product: the same matrix as the full outer products, in 6 of their 9 terms).
  std::array<double, 6> c{};  // xx, xy, xz, yy, yz, zz
  const auto add = [&c](const Eigen::Vector3d& d) {
    c[0] += d.x() * d.x();
    c[1] += d.x() * d.y();
    c[2] += d.x() * d.z();
    c[3] += d.y() * d.y();
    c[4] += d.y() * d.z();
    c[5] += d.z() * d.z();
  };
  add(centre - mean);
  for (const Neighbour& n : neighbours) {
    if (n.same_label) add(n.x - mean);
  }
  for (double& v : c) v /= count;
  Eigen::Matrix3d cov;
  cov << c[0] + regulariser, c[1], c[2], c[1], c[3] + regulariser, c[4], c[2], c[4],
      c[5] + regulariser;
  return cov;
}

namespace {

/// Squared Mahalanobis distances q_j = d^T Sigma^-1 d; k(x_j; s Sigma) = kernel(sqrt(q_j / s)).
/// A neighbour with q_j >= s_max lies outside k(.; s Sigma) for every s <= s_max: its term is
/// the constant target_j^2 (0 for a positive one, whose target is 0 there too), summed once
/// into `outside` instead of evaluated at every s of the search.
/// The arrays are the caller's (fitScale keeps them per thread: no allocation per kernel).
struct Prepared {
  std::vector<double>& q;
  std::vector<double>& target;
  double outside = 0.0;
  double det = 1.0;
};

template <class KernelOfSquared>
Prepared prepare(const Eigen::Matrix3d& sigma, const Eigen::Vector3d& centre,
                 std::span<const Neighbour> neighbours, const KernelOfSquared& kernel,
                 std::vector<double>& q_buffer, std::vector<double>& target_buffer,
                 double s_max = std::numeric_limits<double>::infinity()) {
  Prepared p{q_buffer, target_buffer};
  p.q.clear();
  p.target.clear();
  const Eigen::Matrix3d inverse = sigma.inverse();
  p.det = sigma.determinant();
  p.q.reserve(neighbours.size());
  p.target.reserve(neighbours.size());
  for (const Neighbour& n : neighbours) {
    const Eigen::Vector3d d = n.x - centre;
    const double q = d.dot(inverse * d);
    const double target = n.same_label ? kernel(q) : 0.0;
    if (q >= s_max) {
      p.outside += target * target;
      continue;
    }
    p.q.push_back(q);
    p.target.push_back(target);
  }
  return p;
}

/// Eq. 3.7 with `kernel(r^2)`: the table in the search, the exact kernel in scaleObjective.
template <class KernelOfSquared>
double objective(double s, const Prepared& p, const KernelOfSquared& kernel) {
  const double inverse_s = 1.0 / s;
  double error = p.outside;
  for (std::size_t j = 0; j < p.q.size(); ++j) {
    const double e = p.target[j] - kernel(p.q[j] * inverse_s);
    error += e * e;
  }
  return 0.5 * error / std::sqrt(s * s * s * p.det);
}

double objective(double s, const Prepared& p) { return objective(s, p, squaredKernel()); }

}  // namespace

double scaleObjective(double s, const Eigen::Matrix3d& sigma, const Eigen::Vector3d& centre,
                      std::span<const Neighbour> neighbours) {
  const auto exact = [](double u) { return sparseKernel(std::sqrt(std::max(u, 0.0))); };
  std::vector<double> q, target;
  return objective(s, prepare(sigma, centre, neighbours, exact, q, target), exact);
}

double fitScale(const Eigen::Matrix3d& sigma, const Eigen::Vector3d& centre,
                std::span<const Neighbour> neighbours, double s_min, double s_max) {
  thread_local std::vector<double> q, target;
  const Prepared p = prepare(sigma, centre, neighbours, squaredKernel(), q, target, s_max);
  constexpr double kPerDoubling = 8.0;
  const int i_min = static_cast<int>(std::ceil(std::log2(s_min) * kPerDoubling));
  const int i_max = static_cast<int>(std::floor(std::log2(s_max) * kPerDoubling));
  if (i_min > i_max) return std::clamp(1.0, s_min, s_max);
  const auto at = [&](int i) { return std::exp2(i / kPerDoubling); };
  int i = std::clamp(0, i_min, i_max);
  double f = objective(at(i), p);
  // The walk keeps both neighbours' values: a step re-evaluates only the new far one.
  double down = i > i_min ? objective(at(i - 1), p) : f;
  double up = i < i_max ? objective(at(i + 1), p) : f;
  while (true) {
    if (down < f && down <= up) {
      --i;
      up = f;
      f = down;
      down = i > i_min ? objective(at(i - 1), p) : f;
    } else if (up < f) {
      ++i;
      down = f;
      f = up;
      up = i < i_max ? objective(at(i + 1), p) : f;
    } else {
      break;
    }
  }
  // The parabola through the grid point and its two neighbours (their values are at hand),
  // in log s: its vertex, one evaluation (a golden-section search between the neighbours would
  // take ten for a scale within 0.4%, and the maps do not change measurably).
  if (i > i_min && i < i_max) {
    const double curvature = down - 2.0 * f + up;
    if (curvature > 0.0) {
      const double offset = std::clamp(0.5 * (down - up) / curvature, -1.0, 1.0);
      const double best = std::exp2((i + offset) / kPerDoubling);
      // Never worse than the grid point the descent ended on.
      if (objective(best, p) <= f) return best;
    }
  }
  return at(i);
}

}  // namespace densemap::kernel
