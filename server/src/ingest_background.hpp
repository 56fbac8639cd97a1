#pragma once
// A background re-integration of the ingest's map history (ingest_history.cpp); defined here
// so that ingest.cpp, which owns it, sees its destructor.
#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "densemap/server/ingest.hpp"

namespace densemap::server {

/// A re-integration under way: its thread and whether it has caught up (or failed).
struct Ingest::Background {
  std::uint64_t begin = 0;            // the checkpoint it starts from
  std::unique_ptr<Reintegration> re;  // made by the thread
  std::thread thread;
  std::atomic<bool> cancel{false};
  std::atomic<bool> ready{false};    // caught up, or failed (error)
  std::optional<std::string> error;  // written by the thread before `ready`
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();

  ~Background() {
    cancel = true;
    if (thread.joinable()) thread.join();
  }
};

}  // namespace densemap::server
