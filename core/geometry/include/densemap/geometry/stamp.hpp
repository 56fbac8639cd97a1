#pragma once

#include <cstdint>

namespace densemap {

/// A time in nanoseconds as seconds and nanoseconds, the way ROS (builtin_interfaces/Time) and
/// protobuf (google.protobuf.Timestamp) carry it: seconds floored, nanoseconds in [0, 1e9),
/// also before 1970.
struct SplitStamp {
  std::int64_t sec = 0;
  std::uint32_t nanosec = 0;
};

[[nodiscard]] constexpr SplitStamp splitStamp(std::int64_t ns) {
  constexpr std::int64_t kSecond = 1'000'000'000;
  const std::int64_t sec = ns >= 0 ? ns / kSecond : -((-ns + kSecond - 1) / kSecond);
  return {sec, static_cast<std::uint32_t>(ns - sec * kSecond)};
}

}  // namespace densemap
