#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <numbers>

namespace densemap::kernel {

/// The sparse (compactly supported) kernel of Melkumyan & Ramos that BGKOctoMap and AKIMap use
/// (dissertation Eq. 3.5): 1 at r = 0, smoothly 0 at r >= 1 (and for NaN r).
[[nodiscard]] inline double sparseKernel(double r) {
  if (!(r < 1.0)) return 0.0;
  if (r < 0.0) r = 0.0;
  const double a = 2.0 * std::numbers::pi * r;
  return (2.0 + std::cos(a)) / 3.0 * (1.0 - r) + std::sin(a) / (2.0 * std::numbers::pi);
}

/// sparseKernel(sqrt(u)) for u = r^2 in [0, 1], tabulated for the loops that evaluate it millions
/// of times (the scale search, the free-evidence capsules): linear interpolation in u is within
/// 1e-8 of the exact value (the kernel is smooth in r^2: its derivative in r vanishes at 0),
/// and saves a sqrt and a sincos per term. 0 for u >= 1 and for NaN.
class SquaredKernelTable {
 public:
  static constexpr int kSize = 4096;
  SquaredKernelTable() {
    for (int i = 0; i <= kSize; ++i) {
      values_[static_cast<std::size_t>(i)] =
          sparseKernel(std::sqrt(static_cast<double>(i) / kSize));
    }
  }
  [[nodiscard]] double operator()(double u) const {
    if (!(u < 1.0)) return 0.0;
    const double x = std::max(u, 0.0) * kSize;
    // x in [0, kSize): a signed conversion is one instruction (an unsigned one tests and
    // branches around it on x86-64).
    const auto i = static_cast<std::size_t>(static_cast<int>(x));
    const double f = x - static_cast<double>(static_cast<int>(i));
    return values_[i] + f * (values_[i + 1] - values_[i]);
  }

 private:
  std::array<double, kSize + 1> values_{};
};

/// The one table (built on first use).
[[nodiscard]] inline const SquaredKernelTable& squaredKernel() {
  static const SquaredKernelTable table;
  return table;
}

}  // namespace densemap::kernel
