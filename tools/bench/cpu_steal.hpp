#pragma once

#include <optional>
#include <string_view>

namespace densemap::bench {

/// The machine's CPU time so far (/proc/stat's "cpu" line, in clock ticks): all of it, and the
/// part a hypervisor gave to other guests while this one had work (steal). On a shared VM a
/// method's times move with the steal (the same binary's p50 has doubled under 30-50% steal),
/// so the bench says how much there was while each method ran.
struct CpuTimes {
  unsigned long long total = 0;
  unsigned long long steal = 0;
};

/// The times of a /proc/stat "cpu" line (user nice system idle iowait irq softirq steal ...);
/// nullopt when it is not one (fewer than 8 numbers, or another line).
[[nodiscard]] std::optional<CpuTimes> parseCpuLine(std::string_view line);
/// /proc/stat's times now; nullopt where it cannot be read.
[[nodiscard]] std::optional<CpuTimes> readCpuTimes();

/// Steal and total ticks summed over intervals (each from a reading before to one after).
class StealMeter {
 public:
  void add(const std::optional<CpuTimes>& before, const std::optional<CpuTimes>& after);
  /// The stolen share of the intervals' CPU time; negative when no interval could be read.
  [[nodiscard]] double share() const;

 private:
  unsigned long long total_ = 0, steal_ = 0;
  bool known_ = false;
};

}  // namespace densemap::bench
