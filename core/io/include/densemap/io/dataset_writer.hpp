#pragma once

#include <filesystem>
#include <map>

#include "densemap/geometry/error.hpp"
#include "densemap/io/scan.hpp"

namespace densemap {

/// Writes the dataset directory layout (docs/datasets.md): `DIR/scans/NNNNNN.bin` (float32 x y z
/// intensity, sensor frame) and `DIR/poses.txt` (KITTI 3x4 rows), where line i is the pose of
/// scan number i. Ids need not be contiguous; lines for missing ids hold the identity.
/// Single-writer.
class DatasetWriter {
 public:
  /// Creates `dir/scans`. Existing scan files with the same numbers are overwritten.
  [[nodiscard]] static Expected<DatasetWriter> create(const std::filesystem::path& dir);

  /// Writes one scan; world-frame scans are re-expressed in the sensor frame.
  [[nodiscard]] Expected<void> write(const Scan& scan);
  /// Writes poses.txt (atomically). Call once after the last scan.
  [[nodiscard]] Expected<void> finish();

 private:
  explicit DatasetWriter(std::filesystem::path dir) : dir_(std::move(dir)) {}
  std::filesystem::path dir_;
  std::map<std::size_t, Transform> poses_;
};

}  // namespace densemap
