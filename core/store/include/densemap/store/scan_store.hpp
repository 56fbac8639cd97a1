#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/io/raw_scan.hpp"

namespace densemap {

struct ScanStoreOptions {
  /// Where the store keeps its files: it makes a directory of its own inside (one per store,
  /// removed with it), so several servers may share one.
  std::filesystem::path directory;
  /// Compressed bytes the stored scans may hold on disk; beyond it append() refuses, and the
  /// owner drops the oldest (dropBefore()).
  std::size_t max_bytes = std::size_t{2} << 30;
  /// Scans are written into segment files of about this size; dropBefore() removes whole ones.
  std::size_t segment_bytes = std::size_t{64} << 20;
};

/// The most bytes one record may decode to (a scan of ScanLimits' 2,000,000 points with
/// intensities, and its id): a larger length in a record is corruption, refused before any
/// allocation.
inline constexpr std::size_t kMaxScanRecordBytes = std::size_t{40} << 20;

/// A record as the store writes it: a 16-byte header (magic, compressed and raw lengths, CRC-32
/// of the compressed bytes), then the zlib-compressed scan (its id, seq, stamp, pose, points and
/// intensities).
[[nodiscard]] std::vector<std::uint8_t> encodeScanRecord(const RawScan& scan);
/// Reads one record back. Every length is checked before allocation (kMaxScanRecordBytes), and
/// the CRC and the decoded fields' sizes against each other: an error, never a scan, for bytes
/// that were not written by encodeScanRecord.
[[nodiscard]] Expected<RawScan> decodeScanRecord(std::span<const std::uint8_t> bytes);

/// The scans a server integrated, kept on disk in arrival order so that they can be integrated
/// again with corrected poses (docs/fleet.md, pose corrections). Each scan has an index (0, 1,
/// ... in the order appended); the store keeps [first(), end()), bounded by max_bytes, and each
/// scan's pose, which setPose() replaces. Files: `<directory>/densemap-scans-<pid>-<n>/`, made
/// at create() and removed with the store.
/// Thread-safety: every method from any thread (one mutex; reads decompress outside it).
class ScanStore {
 public:
  [[nodiscard]] static Expected<std::unique_ptr<ScanStore>> create(const ScanStoreOptions& options);
  ~ScanStore();
  ScanStore(const ScanStore&) = delete;
  ScanStore& operator=(const ScanStore&) = delete;

  /// Writes `scan` at index end(). An error (nothing kept) when the write fails or the store
  /// would pass max_bytes.
  [[nodiscard]] Expected<std::uint64_t> append(const RawScan& scan);
  /// Scan `index` as appended, with its current pose (setPose). An error outside
  /// [first(), end()) or for a damaged file.
  [[nodiscard]] Expected<RawScan> read(std::uint64_t index) const;
  /// The latest scan of `sensor_id` stamped `stamp_ns` still kept.
  [[nodiscard]] std::optional<std::uint64_t> find(std::string_view sensor_id,
                                                  std::int64_t stamp_ns) const;
  /// Replaces scan `index`'s pose (translation, quaternion w, x, y, z). False outside the store.
  bool setPose(std::uint64_t index, const std::array<double, 3>& t, const std::array<double, 4>& q);
  /// Forgets the scans before `index` and removes the segment files that hold only them.
  void dropBefore(std::uint64_t index);
  /// Forgets every scan (indices go on from end()).
  void clear() { dropBefore(end()); }

  [[nodiscard]] std::uint64_t first() const;
  [[nodiscard]] std::uint64_t end() const;
  /// Compressed bytes of the kept scans' segments.
  [[nodiscard]] std::size_t bytes() const;
  [[nodiscard]] const std::filesystem::path& directory() const { return directory_; }

 private:
  struct Segment;
  struct Entry {
    std::shared_ptr<Segment> segment;
    std::uint64_t offset = 0;
    std::uint32_t length = 0;
    std::string sensor_id;
    std::int64_t stamp_ns = 0;
    std::array<double, 3> t{};
    std::array<double, 4> q{};
  };
  ScanStore(const ScanStoreOptions& options, std::filesystem::path directory);
  [[nodiscard]] const Entry* entry(std::uint64_t index) const;  // under mutex_

  ScanStoreOptions options_;
  std::filesystem::path directory_;
  mutable std::mutex mutex_;
  std::vector<Entry> entries_;  // index first_ + i
  std::uint64_t first_ = 0;
  std::vector<std::shared_ptr<Segment>> segments_;  // oldest first; the last one is written
  std::size_t bytes_ = 0;
  /// sensor id -> stamp -> index, for find().
  std::unordered_map<std::string, std::map<std::int64_t, std::uint64_t>> by_stamp_;
};

}  // namespace densemap
