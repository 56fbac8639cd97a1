#include "densemap/sim/lidar_simulator.hpp"

#include <tbb/parallel_for.h>

#include <cmath>
#include <random>

namespace densemap {

Scan simulateScan(const Scene& scene, const LidarModel& lidar, const Transform& T_world_sensor,
                  std::size_t scan_id, std::uint64_t seed) {
  const int beams = lidar.beams();
  std::vector<double> cos_e(beams), sin_e(beams);
  for (int b = 0; b < beams; ++b) {
    const double e = lidar.elevations_deg[b] * M_PI / 180.0;
    cos_e[b] = std::cos(e);
    sin_e[b] = std::sin(e);
  }
  struct Column {
    PointCloud points;
    std::vector<float> intensities;
  };
  std::vector<Column> columns(lidar.columns);
  const Eigen::Vector3d origin = T_world_sensor.translation();
  const Eigen::Matrix3d R = T_world_sensor.linear();
  tbb::parallel_for(0, lidar.columns, [&](int c) {
    std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                      static_cast<std::uint32_t>(scan_id), static_cast<std::uint32_t>(c)};
    std::mt19937_64 rng(seq);
    std::normal_distribution<double> noise(0.0, 1.0);
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    const double azimuth = 2.0 * M_PI * c / lidar.columns;
    const double ca = std::cos(azimuth), sa = std::sin(azimuth);
    Column& out = columns[c];
    for (int b = 0; b < beams; ++b) {
      const Eigen::Vector3d dir_sensor(cos_e[b] * ca, cos_e[b] * sa, sin_e[b]);
      const auto range = scene.castRay(origin, R * dir_sensor, lidar.max_range_m);
      // Draw both numbers for every beam so the stream does not depend on what was hit.
      const double n = noise(rng);
      const double drop = uniform(rng);
      if (!range || *range < lidar.min_range_m || drop < lidar.dropout) continue;
      const double r = std::max(lidar.min_range_m, *range + lidar.noise_std_m * n);
      out.points.push_back((dir_sensor * r).cast<float>());
      out.intensities.push_back(static_cast<float>(b));
    }
  });
  Scan scan;
  scan.id = scan_id;
  scan.frame = PointFrame::kSensor;
  scan.T_world_sensor = T_world_sensor;
  for (Column& col : columns) {
    scan.points.insert(scan.points.end(), col.points.begin(), col.points.end());
    scan.intensities.insert(scan.intensities.end(), col.intensities.begin(), col.intensities.end());
  }
  return scan;
}

}  // namespace densemap
