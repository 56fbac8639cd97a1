#pragma once

#include <sys/types.h>

#include <chrono>
#include <filesystem>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/load/runner.hpp"

namespace densemap::load::detail {

/// A query client's result as its process writes it (--processes), and read back.
void writeChildResult(const std::filesystem::path& file, const QueryResult& r);
void readChildResult(const std::filesystem::path& file, QueryResult& r);

/// Child processes running query clients (--processes).
class Children {
 public:
  Expected<void> spawn(const RunOptions& o, const Scenario& scenario, Clock::time_point epoch,
                       const std::filesystem::path& tracks, const std::filesystem::path& dir);
  /// Their CPU time so far, from /proc (while they run; their own final figure comes in their
  /// result files). Each child's figure never goes back: a child that has exited reads as 0 in
  /// /proc, which would make the load tool's CPU share negative.
  double cpuSeconds();
  /// Waits for every child (killing those still running `grace` later) and reads results.
  void collect(std::chrono::seconds grace, std::vector<QueryResult>& results);
  void stop();
  ~Children() { stop(); }

 private:
  std::vector<pid_t> pids_;
  std::vector<std::filesystem::path> outs_;
  std::vector<double> last_cpu_s_;  // per child, the most CPU seen
};

}  // namespace densemap::load::detail
