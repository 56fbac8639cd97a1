#pragma once

#include "densemap/kernel/kernel_evidence.hpp"

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

struct LoadedSnapshot {
  std::unique_ptr<OccupancyMap> map;
  std::uint64_t version = 0;
  std::optional<kernel::KernelEvidence> kernel;  // a dense map's evidence, when saved with it
};

/// What a snapshot's cells hold, for the checks at load.
enum class SnapshotValues {
  kLogOdds,    // log-odds clamped to the sensor model's range
  kUnclamped,  // any finite values (a copy of a map whose kind the writer does not know)
};

/// A map of `backend` holding `view`'s cells (a copy: loaded files, checkpoints to build on).
[[nodiscard]] Expected<std::unique_ptr<OccupancyMap>> mapOfView(const MapView& view,
                                                                const SensorModel& model,
                                                                Backend backend);

/// Writes `view` as a protobuf snapshot (`.dmap`) atomically (temp file, fsync, rename), or as
/// an OctoMap `.bt`/`.ot` when the name says so. `kernel`: a dense map's evidence, of the same
/// version as `view`, saved with it in a .dmap (OctoMap files take the probabilities only); a
/// snapshot with evidence is of the evidence's kind, whatever `values` says.
[[nodiscard]] Expected<std::size_t> saveSnapshot(const MapView& view, const SensorModel& model,
                                                 Backend backend, const std::filesystem::path& file,
                                                 const kernel::KernelEvidence* kernel = nullptr,
                                                 SnapshotValues values = SnapshotValues::kLogOdds);

/// Reads a `.dmap` snapshot into a map of `backend`. Errors for unreadable, truncated or
/// inconsistent files, for a resolution other than `expected_resolution_m` (if > 0), for an
/// invalid sensor model, and for values a map of its kind cannot hold (whatever the format
/// version, CRC or not): a non-finite value; a log-odds map's value outside the sensor model's
/// clamp range; negative or non-finite kernel evidence.
[[nodiscard]] Expected<LoadedSnapshot> loadSnapshot(const std::filesystem::path& file,
                                                    Backend backend, double expected_resolution_m);

/// Generation `g` of the snapshot files of `path`: 0 is `path` (the newest), g > 0 is
/// `path.<g>` (older), -1 is `path.new` (a complete save not yet rotated into place).
[[nodiscard]] std::filesystem::path snapshotGeneration(const std::filesystem::path& path, int g);

/// Saves `view` keeping the last `keep` snapshots (1 .. 100): the new file is written atomically
/// as `path.new`, then `path.<keep-2>` ... `path` move one generation older and `path.new`
/// becomes `path`. A crash at any moment leaves every file complete (a temporary file aside);
/// the newest complete save is `path.new` or `path`.
[[nodiscard]] Expected<std::size_t> saveSnapshotKeeping(
    const MapView& view, const SensorModel& model, Backend backend,
    const std::filesystem::path& path, int keep, const kernel::KernelEvidence* kernel = nullptr);

struct ResumedSnapshot {
  LoadedSnapshot snapshot;
  std::filesystem::path file;        // the generation loaded
  std::vector<std::string> skipped;  // newer generations passed over, with the reason
};

/// Loads the newest readable generation of `path` (`path.new`, `path`, `path.1`, ...
/// `path.<keep-1>`). No file at all: std::nullopt. Files but none readable: an error listing
/// each file and its reason.
[[nodiscard]] Expected<std::optional<ResumedSnapshot>> loadNewestSnapshot(
    const std::filesystem::path& path, int keep, Backend backend, double expected_resolution_m);

}  // namespace densemap
