#pragma once

#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap {

/// A spinning multi-beam LiDAR: a beam elevation table, columns per revolution, range limits
/// and an error model. Defaults describe a clean sensor.
struct LidarModel {
  std::string name;
  std::vector<double> elevations_deg;  // one per beam, top to bottom
  int columns = 1024;                  // azimuth steps per revolution
  double min_range_m = 0.5;
  double max_range_m = 100.0;
  double noise_std_m = 0.0;  // Gaussian range noise
  double dropout = 0.0;      // probability a return is lost

  [[nodiscard]] int beams() const { return static_cast<int>(elevations_deg.size()); }
  /// Errors for empty tables, non-positive columns, bad ranges or probabilities.
  [[nodiscard]] Expected<void> validate() const;
};

/// Beam tables of real sensors: "vlp16" (Velodyne VLP-16, +-15 deg every 2 deg), "hdl64"
/// (Velodyne HDL-64E: +2..-8.33 deg and -8.83..-24.33 deg blocks), "os128" (Ouster OS1-128,
/// +-22.5 deg uniform), "os0-64" (Ouster OS0-64, +-45 deg, like the BALM scans).
[[nodiscard]] Expected<LidarModel> lidarPreset(const std::string& name);

}  // namespace densemap
