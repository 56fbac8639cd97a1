#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/io/raw_scan.hpp"
#include "densemap/pipeline/engine.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/store/scan_store.hpp"

namespace densemap {

/// The settings of a map's history (server config `history`, docs/fleet.md).
struct HistoryOptions {
  ScanStoreOptions store;
  /// A checkpoint (a kept version of the map) every this many scans: a correction is
  /// re-integrated from the latest checkpoint before its earliest scan. 1 .. 1,000,000.
  std::size_t checkpoint_every = 250;
  /// Checkpoints kept (1 .. 1024): the oldest bounds how far back a correction may reach; its
  /// scans and older are dropped from the store when a newer one is taken. Each holds the
  /// blocks that changed after it (copy-on-write), so memory grows with what the map changed.
  std::size_t max_checkpoints = 8;
};

/// A correction from outside: its sensor id (checkSensorId), at most kMaxCorrectedPoses poses,
/// each pose by the scans' rule (checkScanPose). The error names the first bad pose.
[[nodiscard]] Expected<void> checkCorrection(const PoseCorrection& correction,
                                             const ScanLimits& limits);

/// A kept version of the map: the scans before `index` are in `view`.
struct Checkpoint {
  std::uint64_t index = 0;
  std::shared_ptr<const MapView> view;
};

/// What correct() did.
struct CorrectionOutcome {
  std::size_t corrected = 0;              // kept scans whose pose was replaced
  std::size_t unmatched = 0;              // poses with no kept scan of that sensor and stamp
  std::optional<std::uint64_t> earliest;  // the earliest corrected scan's index
};

/// A map's history (docs/fleet.md, pose corrections): the scans integrated since its oldest
/// checkpoint, in the order integrated (a ScanStore), and checkpoints every `checkpoint_every`
/// scans. The map's writer records each scan after integrating it; a correction replaces
/// stored poses, and a Reintegration rebuilds the map from the checkpoint before the earliest.
/// A change that is not a scan's (a reset, a cleared box, a loaded map) restarts the history.
/// Thread-safety: record/restart/correct from the map's writer; the rest from any thread.
class ScanHistory {
 public:
  /// A history whose first checkpoint is `base` (the map before its first recorded scan).
  [[nodiscard]] static Expected<std::unique_ptr<ScanHistory>> create(
      const HistoryOptions& options, std::shared_ptr<const MapView> base);

  /// After `scan` was integrated and `view` published: stores the scan and takes a checkpoint
  /// when one is due, dropping the oldest past max_checkpoints (and when the store is full). An
  /// error when the scan cannot be stored: the history then restarts from `view`.
  [[nodiscard]] Expected<void> record(const RawScan& scan, std::shared_ptr<const MapView> view);
  /// The map changed other than by a scan: the history starts again from `view`.
  void restart(std::shared_ptr<const MapView> view);
  /// Replaces the stored poses the correction names (the caller checked it: checkCorrection).
  CorrectionOutcome correct(const PoseCorrection& correction);

  /// The latest checkpoint at or before scan `index` (none before the oldest).
  [[nodiscard]] std::optional<Checkpoint> checkpointBefore(std::uint64_t index) const;
  /// Whether a checkpoint is kept at `index`.
  [[nodiscard]] bool hasCheckpointAt(std::uint64_t index) const;
  /// Replaces the checkpoints at the same indices as `rebuilt`'s (a Reintegration's, once the
  /// map equals it).
  void replaceCheckpoints(const std::vector<Checkpoint>& rebuilt);

  [[nodiscard]] const ScanStore& store() const { return *store_; }
  [[nodiscard]] std::size_t checkpoints() const;
  /// The index of the oldest scan a correction may still reach.
  [[nodiscard]] std::uint64_t oldestCorrectable() const;
  [[nodiscard]] const HistoryOptions& options() const { return options_; }

 private:
  ScanHistory(const HistoryOptions& options, std::unique_ptr<ScanStore> store);
  void dropOldestCheckpoint();  // under mutex_

  HistoryOptions options_;
  std::unique_ptr<ScanStore> store_;
  mutable std::mutex mutex_;
  std::vector<Checkpoint> checkpoints_;  // oldest first, indices increasing
};

/// Builds a map again from a checkpoint (docs/fleet.md): a new engine over a copy of the
/// checkpoint's cells integrates the stored scans from there with their current poses. It runs
/// beside the live map (advance() from a background thread), then the live map's writer
/// finishes the last scans and patch()es the live map to equal it. The result equals, cell
/// for cell, the map built from scratch with the corrected poses: a log-odds cell depends
/// only on the rays through it, in order.
class Reintegration {
 public:
  /// `options`: the live engine's (a log-odds map kind); views are versioned so that the
  /// checkpoints taken on the way stay valid.
  [[nodiscard]] static Expected<std::unique_ptr<Reintegration>> create(
      const PipelineOptions& options, const Checkpoint& from);

  /// Integrates the stored scans [next(), until) with their current poses, taking a checkpoint
  /// wherever `history` keeps one; returns early (no error) once `cancel` is set. An error for a
  /// scan the store cannot read. A scan the engine rejects is skipped, as it was live.
  [[nodiscard]] Expected<void> advance(const ScanHistory& history, std::uint64_t until,
                                       const std::atomic<bool>* cancel = nullptr);
  [[nodiscard]] std::uint64_t begin() const { return begin_; }
  [[nodiscard]] std::uint64_t next() const { return next_; }
  [[nodiscard]] const std::vector<Checkpoint>& checkpoints() const { return checkpoints_; }
  [[nodiscard]] std::shared_ptr<const MapView> view() const { return engine_->view(); }

  /// Makes `live` (whose latest version is `live_view`) hold this map's cells: the cells that
  /// differ are set or erased and appended to `changes`. Returns how many.
  std::size_t patch(OccupancyMap& live, const MapView& live_view, CellChanges& changes) const;

 private:
  Reintegration(std::unique_ptr<Engine> engine, std::uint64_t begin);

  std::unique_ptr<Engine> engine_;
  std::uint64_t begin_ = 0;
  std::uint64_t next_ = 0;
  std::vector<Checkpoint> checkpoints_;
};

}  // namespace densemap
