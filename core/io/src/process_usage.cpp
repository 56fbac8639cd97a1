#include "densemap/io/process_usage.hpp"

#include <unistd.h>

#include <fstream>
#include <sstream>
#include <string>

namespace densemap {

ProcessUsage processUsage(int pid) {
  const std::string dir = pid == 0 ? "/proc/self" : "/proc/" + std::to_string(pid);
  ProcessUsage u;
  // statm: size resident ... in pages.
  std::ifstream statm(dir + "/statm");
  std::uint64_t size = 0, resident = 0;
  if (statm >> size >> resident) {
    u.rss_bytes = resident * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
  }
  // stat: the command name is in parentheses and may hold spaces; fields 14 and 15 (utime,
  // stime, in clock ticks) follow the closing parenthesis as the 12th and 13th words.
  std::ifstream stat(dir + "/stat");
  std::string line;
  if (std::getline(stat, line)) {
    const auto close = line.rfind(')');
    if (close != std::string::npos) {
      std::istringstream rest(line.substr(close + 1));
      std::string word;
      double ticks = 0;
      for (int field = 3; field <= 15 && rest >> word; ++field) {
        if (field >= 14) ticks += std::stod(word);
      }
      u.cpu_s = ticks / static_cast<double>(sysconf(_SC_CLK_TCK));
    }
  }
  return u;
}

MachineCpu machineCpu() {
  std::ifstream stat("/proc/stat");
  std::string cpu;
  MachineCpu m;
  if (!(stat >> cpu) || cpu != "cpu") return m;
  double value = 0;
  for (int field = 0; field < 8 && stat >> value; ++field) {  // guest time is in user
    m.total_s += value;
    if (field != 3 && field != 4) m.busy_s += value;  // idle, iowait
  }
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  m.busy_s /= tick;
  m.total_s /= tick;
  return m;
}

}  // namespace densemap
