#pragma once

namespace densemap {

/// std::floor and std::ceil of a double whose result fits an int, as the same integers, without
/// their ~25-instruction sequence on a processor without SSE4.1 (the build targets plain
/// x86-64): the truncation, moved by one where it rounded the other way. The caller keeps v
/// inside int's range (clamped first where it may be infinite).
[[nodiscard]] inline int floorToInt(double v) {
  const int t = static_cast<int>(v);
  return t - (static_cast<double>(t) > v ? 1 : 0);
}
[[nodiscard]] inline int ceilToInt(double v) {
  const int t = static_cast<int>(v);
  return t + (static_cast<double>(t) < v ? 1 : 0);
}

}  // namespace densemap
