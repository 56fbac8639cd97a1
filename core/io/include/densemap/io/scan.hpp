#pragma once

#include <cstddef>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/rigid_transform.hpp"

namespace densemap {

enum class PointFrame { kSensor, kWorld };

/// One LiDAR measurement as read from disk: its points, the frame they are in, and the sensor
/// pose. Datasets that store world-frame points (la3dm PCDs, the AKIMap sample) keep them as
/// they are: re-expressing them in the sensor frame would change their float rounding.
struct Scan {
  std::size_t id = 0;
  PointFrame frame = PointFrame::kSensor;
  Transform T_world_sensor = Transform::Identity();
  PointCloud points;
  std::vector<float> intensities;  // empty, or one per point

  /// The points in the world frame (transformed once, in double, if they are sensor-frame).
  [[nodiscard]] PointCloud pointsWorld() const;
  /// The ray origin in the world frame.
  [[nodiscard]] Point3f originWorld() const { return sensorOrigin(T_world_sensor); }
};

}  // namespace densemap
