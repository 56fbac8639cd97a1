#pragma once

#include <filesystem>
#include <limits>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// Writes any backend as an OctoMap file for OctoMap's tools (octovis, binvox...): `.bt`
/// (binary, maximum-likelihood free/occupied) or `.ot` (full log-odds). Written atomically.
[[nodiscard]] Expected<void> exportOctomap(const OccupancyMap& map,
                                           const std::filesystem::path& file);

/// The value a cell gets where OctoMap keeps only occupied / free (.bt, writeBinaryData):
/// OctoMap calls log-odds >= 0 occupied, densemap > 0, so a cell at exactly 0 (a kernel map's
/// p = 0.5) is written as the nearest free value; every other value as it is.
[[nodiscard]] inline float octomapClassValue(float log_odds) {
  return log_odds == 0.0F ? -std::numeric_limits<float>::denorm_min() : log_odds;
}

/// Reads an OctoMap `.bt` or `.ot` file into a map of the given backend at the file's
/// resolution (ground truth scenes, snapshots from OctoMap users).
[[nodiscard]] Expected<std::unique_ptr<OccupancyMap>> importOctomap(
    const std::filesystem::path& file, Backend backend);

}  // namespace densemap
