#pragma once

#include <cstdint>

namespace densemap {

/// A process's resident memory and CPU time (user + system), read from /proc.
struct ProcessUsage {
  std::uint64_t rss_bytes = 0;
  double cpu_s = 0;
};

/// Of process `pid` (0: this one); zeros when /proc cannot be read (no such process).
[[nodiscard]] ProcessUsage processUsage(int pid = 0);

/// The whole machine's CPU time since boot, all cores together (/proc/stat): busy (everything
/// but idle and iowait) and total, in seconds. Busy / total between two samples is the load.
struct MachineCpu {
  double busy_s = 0;
  double total_s = 0;
};
[[nodiscard]] MachineCpu machineCpu();

}  // namespace densemap
