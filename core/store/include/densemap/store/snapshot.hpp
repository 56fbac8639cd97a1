#pragma once

#include <filesystem>
#include <memory>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"
#include "densemap/pipeline/map_view.hpp"

namespace densemap {

struct LoadedSnapshot {
  std::unique_ptr<OccupancyMap> map;
  std::uint64_t version = 0;
};

/// Writes `view` as a protobuf snapshot (`.dmap`) atomically (temp file, fsync, rename), or as
/// an OctoMap `.bt`/`.ot` when the name says so.
[[nodiscard]] Expected<std::size_t> saveSnapshot(const MapView& view, const SensorModel& model,
                                                 Backend backend,
                                                 const std::filesystem::path& file);

/// Reads a `.dmap` snapshot into a map of `backend`. Errors for unreadable, truncated or
/// inconsistent files, and for a resolution other than `expected_resolution_m` (if > 0).
[[nodiscard]] Expected<LoadedSnapshot> loadSnapshot(const std::filesystem::path& file,
                                                    Backend backend, double expected_resolution_m);

}  // namespace densemap
