#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>

#include "densemap/geometry/error.hpp"
#include "densemap/sim/lidar_model.hpp"

namespace densemap {

/// Everything `densemap-sim` needs to write one dataset. Defaults: a short outdoor drive with
/// a 64-beam sensor, noise-free.
struct SequenceOptions {
  std::string scene = "outdoor";  // "indoor", "outdoor" or a .bt file
  std::string sensor = "hdl64";   // a lidarPreset name
  int columns = 0;                // 0: the preset's
  double max_range_m = 0.0;       // 0: the preset's
  double noise_std_m = 0.0;
  double dropout = 0.0;
  int scans = 10;
  std::uint64_t seed = 1;
  double ground_truth_resolution_m = 0.2;  // 0: no ground truth file
};

struct SequenceSummary {
  std::size_t scans = 0;
  std::size_t points = 0;
  std::filesystem::path ground_truth;  // empty when not written
};

/// Writes `dir/scans/*.bin`, `dir/poses.txt`, `dir/ground_truth.bt` and `dir/sim.txt` (the
/// options used). `progress(done, total)` is called after every scan.
[[nodiscard]] Expected<SequenceSummary> writeSimulatedSequence(
    const SequenceOptions& options, const std::filesystem::path& dir,
    const std::function<void(std::size_t, std::size_t)>& progress = {});

}  // namespace densemap
