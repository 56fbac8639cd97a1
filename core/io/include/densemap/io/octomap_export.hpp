#pragma once

#include <filesystem>
#include <iosfwd>
#include <limits>

#include "densemap/geometry/error.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace octomap {
class OcTree;
}

namespace densemap {

/// OctoMap's binary file (`.bt`) of `tree`, byte for byte what OcTree::writeBinaryConst writes,
/// without its debug lines on stderr (Debian's liboctomap prints "Writing N nodes to output
/// stream... done." on every call: a bare " done." in a daemon's log). False when `out` fails.
[[nodiscard]] bool writeOctomapBinary(const octomap::OcTree& tree, std::ostream& out);

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
