#pragma once

#include <cmath>
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

}  // namespace densemap::kernel
