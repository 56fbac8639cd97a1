#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/sim/lidar_model.hpp"

namespace densemap {

/// Everything `densemap-sim` needs to write one dataset. Defaults: a short outdoor drive with
/// a 64-beam sensor, noise-free.
struct SequenceOptions {
  std::string scene = "outdoor";  // "indoor", "outdoor" or a .bt file
  std::string sensor = "hdl64";   // a lidarPreset name
  int columns = 0;                // 0: the preset's
  /// > 0: replace the preset's beam table by this many beams spread evenly from `top_deg` down
  /// to `bottom_deg` (a sensor of another vertical resolution in the same field of view).
  int beams = 0;
  double top_deg = 15.0;
  double bottom_deg = -15.0;
  double max_range_m = 0.0;       // 0: the preset's
  double noise_std_m = 0.0;
  double dropout = 0.0;
  int scans = 10;
  std::uint64_t seed = 1;
  double ground_truth_resolution_m = 0.2;  // 0: no ground truth file
  /// Keep at most this many points per scan, drawn at random (0: all): sparse scans like the
  /// la3dm / AKIMap benchmarks' 3,500.
  std::size_t points_per_scan = 0;
  /// Dense-oracle labels (oracle_labels.hpp): a noise-free sensor with this factor times the
  /// beams and columns, from the same poses, at each of `oracle_resolutions` (0: none).
  int oracle_factor = 0;
  std::vector<double> oracle_resolutions = {0.1, 0.05};
  /// People walking beside the path (walkersAt), scans 0.1 s apart: what a map that forgets
  /// (map.decay) is for. The ground truth and oracle labels hold the static scene only.
  int walkers = 0;
};

struct SequenceSummary {
  std::size_t scans = 0;
  std::size_t points = 0;
  std::filesystem::path ground_truth;  // empty when not written
  std::vector<std::filesystem::path> oracle_labels;
};

/// Writes `dir/scans/*.bin`, `dir/poses.txt`, `dir/ground_truth.bt`, `dir/oracle_<res>.bt` when
/// asked, and `dir/sim.txt` (the options used). `progress(done, total)` is called after every scan.
[[nodiscard]] Expected<SequenceSummary> writeSimulatedSequence(
    const SequenceOptions& options, const std::filesystem::path& dir,
    const std::function<void(std::size_t, std::size_t)>& progress = {});

}  // namespace densemap
