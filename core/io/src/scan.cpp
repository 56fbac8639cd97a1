#include "densemap/io/scan.hpp"

#include <octomap/math/Pose6D.h>

namespace densemap {
namespace {

octomath::Pose6D toPose6D(const OctomapPose& pose) {
  return {octomath::Vector3(pose.t[0], pose.t[1], pose.t[2]),
          octomath::Quaternion(pose.q[0], pose.q[1], pose.q[2], pose.q[3])};
}

}  // namespace

PointCloud Scan::pointsWorld() const {
  if (frame == PointFrame::kWorld) return points;
  if (!octomap_pose) return transformPoints(T_world_sensor, points);
  // graph2tree: Pointcloud::transform(pose), i.e. pose.transform(p) per point, in float.
  const octomath::Pose6D pose = toPose6D(*octomap_pose);
  PointCloud world;
  world.reserve(points.size());
  for (const Point3f& p : points) {
    const octomath::Vector3 w = pose.transform(octomath::Vector3(p.x(), p.y(), p.z()));
    world.emplace_back(w.x(), w.y(), w.z());
  }
  return world;
}

std::size_t Scan::removeNonFinitePoints() {
  const bool with_intensity = intensities.size() == points.size();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    points[kept] = points[i];
    if (with_intensity) intensities[kept] = intensities[i];
    ++kept;
  }
  const std::size_t removed = points.size() - kept;
  points.resize(kept);
  if (with_intensity) intensities.resize(kept);
  return removed;
}

Point3f Scan::originWorld() const {
  if (frame == PointFrame::kWorld || !octomap_pose) return sensorOrigin(T_world_sensor);
  // graph2tree takes the sensor origin into the scan frame and back: not always the float
  // translation itself.
  const octomath::Pose6D pose = toPose6D(*octomap_pose);
  const octomath::Vector3 o = pose.transform(pose.inv().transform(pose.trans()));
  return {o.x(), o.y(), o.z()};
}

Transform transformFromOctomapPose(const OctomapPose& pose) {
  return transformFromTranslationQuaternion({pose.t[0], pose.t[1], pose.t[2]}, pose.q[0], pose.q[1],
                                            pose.q[2], pose.q[3]);
}

}  // namespace densemap
