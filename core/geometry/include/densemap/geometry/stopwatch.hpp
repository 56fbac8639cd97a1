#pragma once

#include <chrono>

namespace densemap {

/// Milliseconds since `t0`, which then moves to now: consecutive calls time consecutive stages.
inline double msSince(std::chrono::steady_clock::time_point& t0) {
  const auto now = std::chrono::steady_clock::now();
  const double ms = std::chrono::duration<double, std::milli>(now - t0).count();
  t0 = now;
  return ms;
}

}  // namespace densemap
