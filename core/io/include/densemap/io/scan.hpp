#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/rigid_transform.hpp"
#include "densemap/io/raw_scan.hpp"

namespace densemap {

enum class PointFrame { kSensor, kWorld };

/// A pose as OctoMap's `pose6d` holds it: float translation and unit quaternion (w, x, y, z).
struct OctomapPose {
  std::array<float, 3> t{0, 0, 0};
  std::array<float, 4> q{1, 0, 0, 0};
};

/// One LiDAR measurement as read from disk: its points, the frame they are in, and the sensor
/// pose. Datasets that store world-frame points (la3dm PCDs, the AKIMap sample) keep them as
/// they are: re-expressing them in the sensor frame would change their float rounding.
struct Scan {
  std::size_t id = 0;
  PointFrame frame = PointFrame::kSensor;
  Transform T_world_sensor = Transform::Identity();
  PointCloud points;
  std::vector<float> intensities;  // empty, or one per point
  /// Set by the readers of OctoMap's own formats (.graph, scan.dat): the pose exactly as
  /// OctoMap's tools hold it. pointsWorld() and originWorld() then transform a sensor-frame scan
  /// with OctoMap's float arithmetic (liboctomath) as graph2tree does, so that densemap-map and
  /// graph2tree build the same tree. T_world_sensor holds the same pose in double.
  std::optional<OctomapPose> octomap_pose;
  /// When the scan was taken (ns), where the format records it (ROS 2 recordings); replay's
  /// --recorded-rate paces by it.
  std::optional<std::int64_t> stamp_ns;

  /// The points in the world frame: transformed once, in double (or as graph2tree does, with
  /// `octomap_pose`), if they are sensor-frame.
  [[nodiscard]] PointCloud pointsWorld() const;
  /// The ray origin in the world frame.
  [[nodiscard]] Point3f originWorld() const;
  /// Drops NaN/Inf points (a sensor's missing returns) with their intensities; returns how many.
  std::size_t removeNonFinitePoints();
};

/// The same pose in double (for consumers that take sensor-frame scans with a pose).
[[nodiscard]] Transform transformFromOctomapPose(const OctomapPose& pose);

/// A transform in the raw form scans and pose corrections carry (ScanPose).
[[nodiscard]] ScanPose toScanPose(const Transform& T);
/// The transform of a raw pose (quaternion normalized).
[[nodiscard]] Transform fromScanPose(const std::array<double, 3>& t,
                                     const std::array<double, 4>& q);
/// `T_world_sensor` as the pose of the scan stamped `stamp_ns` (toScanPose).
[[nodiscard]] CorrectedPose toCorrectedPose(std::int64_t stamp_ns, const Transform& T_world_sensor);

}  // namespace densemap
