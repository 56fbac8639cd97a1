#include "densemap/io/raw_scan.hpp"

#include "densemap/io/scan.hpp"

namespace densemap {

ScanPose toScanPose(const Transform& T) {
  const Eigen::Quaterniond q(T.linear());
  const Eigen::Vector3d t = T.translation();
  return {{t.x(), t.y(), t.z()}, {q.w(), q.x(), q.y(), q.z()}};
}

Transform fromScanPose(const std::array<double, 3>& t, const std::array<double, 4>& q) {
  Transform T = Transform::Identity();
  T.linear() = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  T.translation() = Eigen::Vector3d(t[0], t[1], t[2]);
  return T;
}

CorrectedPose toCorrectedPose(std::int64_t stamp_ns, const Transform& T_world_sensor) {
  const ScanPose pose = toScanPose(T_world_sensor);
  return {stamp_ns, pose.t, pose.q};
}

RawScan toRawScan(const Scan& scan, std::uint64_t seq, const std::string& sensor_id) {
  RawScan raw;
  raw.sensor_id = sensor_id;
  raw.seq = seq;
  raw.stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::system_clock::now().time_since_epoch())
                     .count();
  const ScanPose pose = toScanPose(scan.T_world_sensor);
  raw.t_world_sensor = pose.t;
  raw.q_world_sensor = pose.q;
  const PointCloud points = scan.frame == PointFrame::kSensor
                                ? scan.points
                                : transformPoints(scan.T_world_sensor.inverse(), scan.points);
  raw.xyz.reserve(points.size() * 3);
  for (const auto& p : points) raw.xyz.insert(raw.xyz.end(), {p.x(), p.y(), p.z()});
  if (scan.intensities.size() == points.size()) raw.intensity = scan.intensities;
  return raw;
}

}  // namespace densemap
