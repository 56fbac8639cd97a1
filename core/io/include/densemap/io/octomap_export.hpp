#pragma once

#include <filesystem>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// Writes any backend as an OctoMap file for OctoMap's tools (octovis, binvox...): `.bt`
/// (binary, maximum-likelihood free/occupied) or `.ot` (full log-odds). Written atomically.
[[nodiscard]] Expected<void> exportOctomap(const OccupancyMap& map,
                                           const std::filesystem::path& file);

/// Reads an OctoMap `.bt` or `.ot` file into a map of the given backend at the file's
/// resolution (ground truth scenes, snapshots from OctoMap users).
[[nodiscard]] Expected<std::unique_ptr<OccupancyMap>> importOctomap(
    const std::filesystem::path& file, Backend backend);

}  // namespace densemap
