#pragma once

// Module-private: the KITTI-style pieces shared by the sensor-frame and world-frame readers.

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/io/scan.hpp"

namespace densemap::kitti {

/// One pose per line: 12 numbers, the first three rows of T_world_sensor, row-major.
[[nodiscard]] Expected<std::vector<Transform>> readPoses(const std::filesystem::path& file);

/// float32 [x y z intensity] records; errors for a size that is not a multiple of 16 or
/// non-finite coordinates are kept (validation happens where scans are integrated).
[[nodiscard]] Expected<void> readPoints(const std::filesystem::path& file, Scan& scan);

/// `dir/*.bin` named by a scan number, sorted by that number.
[[nodiscard]] Expected<std::map<std::size_t, std::filesystem::path>> listNumberedBins(
    const std::filesystem::path& dir);

/// A directory of numbered .bin files with a pose file; `frame` says where the points are.
[[nodiscard]] Expected<std::unique_ptr<class ScanSource>> openNumberedDirectory(
    const std::filesystem::path& scans_dir, const std::filesystem::path& poses_file,
    PointFrame frame, const std::string& format_name);

}  // namespace densemap::kitti
