#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/server/ingest.hpp"

namespace densemap::server {

/// Saves the latest map version (a command's save, the autosave, the one at shutdown), and
/// counts the failures for the status. Thread-safe.
class SnapshotSaver {
 public:
  /// `path`: the configured snapshot (empty: none), kept in `keep` generations.
  SnapshotSaver(Ingest& ingest, std::filesystem::path path, int keep)
      : ingest_(ingest), path_(std::move(path)), keep_(keep) {}

  /// Saves to `file`, or the configured path (its generations rotated); a failure is counted.
  [[nodiscard]] Expected<std::size_t> save(const std::filesystem::path& file = {});
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::uint64_t failures() const { return failures_.load(); }
  [[nodiscard]] std::string lastError() const;

 private:
  [[nodiscard]] Expected<std::size_t> saveUncounted(const std::filesystem::path& file);

  Ingest& ingest_;
  std::filesystem::path path_;
  int keep_;
  std::mutex save_mutex_;  // one rotation at a time (command save, autosave, shutdown)
  std::atomic<std::uint64_t> failures_{0};
  mutable std::mutex error_mutex_;
  std::string last_error_;
};

/// After work that allocates and frees a copy of the map (a snapshot, a late joiner's tiles):
/// hands the freed memory back to the system. glibc keeps freed memory in per-thread arenas,
/// so without this a daemon's RSS climbs to the sum of each thread's peak (seen as +10% steps
/// in a 2-minute soak).
struct ReturnFreeMemory {
  ReturnFreeMemory() = default;
  ReturnFreeMemory(const ReturnFreeMemory&) = delete;
  ReturnFreeMemory& operator=(const ReturnFreeMemory&) = delete;
  ~ReturnFreeMemory();
};

}  // namespace densemap::server
