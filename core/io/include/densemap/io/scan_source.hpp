#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/io/scan.hpp"

namespace densemap {

/// A sequence of scans on disk, loaded one at a time. Thread-safety: const methods are safe to
/// call concurrently.
class ScanSource {
 public:
  virtual ~ScanSource() = default;
  [[nodiscard]] virtual std::size_t size() const = 0;
  /// Scan `index` of the sequence (0-based position, not the scan's id).
  [[nodiscard]] virtual Expected<Scan> load(std::size_t index) const = 0;
  /// Format and location, for progress and logs.
  [[nodiscard]] virtual std::string describe() const = 0;
};

/// Opens any dataset format densemap reads (docs/datasets.md):
/// - a directory with `scans/NNNNNN.bin` and `poses.txt` or `poses_kitti.txt` (sensor frame);
/// - a directory with `clouds_world/NNNNNN.bin` and `sensor_poses_kitti.txt` (world frame);
/// - a directory of la3dm `.pcd` files with VIEWPOINT (world frame), or one `.pcd` file;
/// - an OctoMap ScanGraph `.graph` file; an OctoMap `scan.dat` / `.dat.bz2` text file.
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openScanSource(
    const std::filesystem::path& path);

/// Scans already in memory (parsed whole-file formats, tests, the simulator).
class MemoryScanSource final : public ScanSource {
 public:
  MemoryScanSource(std::vector<Scan> scans, std::string description)
      : scans_(std::move(scans)), description_(std::move(description)) {}
  [[nodiscard]] std::size_t size() const override { return scans_.size(); }
  [[nodiscard]] Expected<Scan> load(std::size_t index) const override;
  [[nodiscard]] std::string describe() const override { return description_; }

 private:
  std::vector<Scan> scans_;
  std::string description_;
};

// Individual formats, for callers that know what they have.
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openDatasetDirectory(
    const std::filesystem::path& dir);
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openWorldCloudDirectory(
    const std::filesystem::path& dir);
[[nodiscard]] Expected<std::unique_ptr<ScanSource>> openPcdDirectory(
    const std::filesystem::path& dir);
[[nodiscard]] Expected<Scan> readPcd(const std::filesystem::path& file);
[[nodiscard]] Expected<std::vector<Scan>> readScanGraph(const std::filesystem::path& file);
[[nodiscard]] Expected<std::vector<Scan>> readScanDat(const std::filesystem::path& file);

/// Writes scans [first, first + count) of `source` as an OctoMap ScanGraph (`.graph`, what
/// graph2tree, octovis and OctoMap's ScanGraph read), atomically, without edges. Sensor-frame
/// scans keep their points and pose (their OctoMap pose, or the double pose rounded to float);
/// world-frame scans are stored relative to their origin, unrotated. `progress(n)` is called
/// after the n-th scan.
[[nodiscard]] Expected<void> writeScanGraph(
    const ScanSource& source, std::size_t first, std::size_t count,
    const std::filesystem::path& file, const std::function<void(std::size_t)>& progress = {});

}  // namespace densemap
