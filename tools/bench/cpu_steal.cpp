#include "cpu_steal.hpp"

#include <charconv>
#include <fstream>
#include <string>

namespace densemap::bench {

std::optional<CpuTimes> parseCpuLine(std::string_view line) {
  constexpr std::string_view kPrefix = "cpu ";
  if (line.substr(0, kPrefix.size()) != kPrefix) return std::nullopt;
  line.remove_prefix(kPrefix.size());
  // user nice system idle iowait irq softirq steal: the total is their sum (guest time is
  // already inside user's).
  CpuTimes t;
  for (int field = 0; field < 8; ++field) {
    while (!line.empty() && line.front() == ' ') line.remove_prefix(1);
    unsigned long long value = 0;
    const auto [end, error] = std::from_chars(line.data(), line.data() + line.size(), value);
    if (error != std::errc() || end == line.data()) return std::nullopt;
    line.remove_prefix(static_cast<std::size_t>(end - line.data()));
    t.total += value;
    if (field == 7) t.steal = value;
  }
  return t;
}

std::optional<CpuTimes> readCpuTimes() {
  std::ifstream stat("/proc/stat");
  std::string line;
  if (!std::getline(stat, line)) return std::nullopt;
  return parseCpuLine(line);
}

void StealMeter::add(const std::optional<CpuTimes>& before, const std::optional<CpuTimes>& after) {
  if (!before || !after || after->total < before->total || after->steal < before->steal) return;
  total_ += after->total - before->total;
  steal_ += after->steal - before->steal;
  known_ = true;
}

double StealMeter::share() const {
  if (!known_) return -1.0;
  return total_ > 0 ? static_cast<double>(steal_) / static_cast<double>(total_) : 0.0;
}

}  // namespace densemap::bench
