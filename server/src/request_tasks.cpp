#include "request_tasks.hpp"

#include <malloc.h>
#include <spdlog/spdlog.h>

#include <algorithm>

namespace densemap::server {

namespace {

// Once this many request bytes were served and none is in flight, trimIfIdle hands the heap's
// free memory back to the OS.
constexpr std::size_t kTrimAfterBytes = std::size_t{16} << 20;

}  // namespace

void RequestStats::refused(const std::string& error) {
  spdlog::debug("refused request: {}", error);
  ++refused_;
  std::lock_guard lock(mutex_);
  last_error_ = error;
}

std::string RequestStats::lastError() const {
  std::lock_guard lock(mutex_);
  return last_error_;
}

RequestTasks::RequestTasks(int threads, std::size_t budget_bytes)
    : budget_bytes_(budget_bytes),
      // No slot kept for a master (the service thread only enqueues); high priority, so free
      // workers take queries before integration's spare work.
      arena_(std::max(1, threads), 0, tbb::task_arena::priority::high) {}

void RequestTasks::run(std::function<void()> task, std::size_t bytes) {
  ++in_flight_;
  bytes_ += bytes;
  arena_.execute([&] {
    tasks_.run([this, bytes, task = std::move(task)] {
      task();
      bytes_ -= bytes;
      served_since_trim_ += bytes;
      --in_flight_;
    });
  });
}

void RequestTasks::trimIfIdle() {
  // At the status tick, a second or so after the last reply: its serialised copy leaves DDS's
  // writer history once the asker acknowledged it.
  if (bytes_.load() == 0 && served_since_trim_.load() > kTrimAfterBytes) {
    served_since_trim_ = 0;
    malloc_trim(0);
  }
}

void RequestTasks::wait() {
  arena_.execute([this] { tasks_.wait(); });
}

}  // namespace densemap::server
