#pragma once

#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>

namespace densemap::server {

/// Requests answered and refused, and the last refusal (the status's query counters).
/// Thread-safe.
class RequestStats {
 public:
  void answered() { ++answered_; }
  /// A refused request (a query or a command): counted, its reason kept as the last error.
  void refused(const std::string& error);
  [[nodiscard]] std::uint64_t answeredCount() const { return answered_.load(); }
  [[nodiscard]] std::uint64_t refusedCount() const { return refused_.load(); }
  [[nodiscard]] std::string lastError() const;

 private:
  std::atomic<std::uint64_t> answered_{0}, refused_{0};
  mutable std::mutex mutex_;
  std::string last_error_;
};

/// The task arena requests are answered in (point / bbox / ray queries, send-map), with the
/// memory budget of the requests in flight (pipeline.request_budget_mb). Thread-safe.
class RequestTasks {
 public:
  /// At most this many tasks in flight; beyond, requests stay in the DDS readers (keep-last).
  static constexpr int kMaxInFlight = 64;

  RequestTasks(int threads, std::size_t budget_bytes);
  /// Runs `task` in the arena; `bytes` is charged to the budget while it runs.
  void run(std::function<void()> task, std::size_t bytes = 0);
  /// Whether another request may be taken now (tasks and bytes under their limits).
  [[nodiscard]] bool roomForMore() const {
    return in_flight_.load() < kMaxInFlight && bytes_.load() < budget_bytes_;
  }
  [[nodiscard]] std::size_t budgetBytes() const { return budget_bytes_; }
  /// When enough request bytes were served and none is in flight: the heap's free memory goes
  /// back to the OS (a point-query flood's RSS stayed until a save trimmed it).
  void trimIfIdle();
  /// Waits for every task in flight (stop()).
  void wait();

 private:
  std::size_t budget_bytes_;
  tbb::task_arena arena_;
  tbb::task_group tasks_;
  std::atomic<int> in_flight_{0};
  std::atomic<std::size_t> bytes_{0};              // charged to budget_bytes_
  std::atomic<std::size_t> served_since_trim_{0};  // request bytes answered since the last trim
};

}  // namespace densemap::server
