#include "densemap/io/raw_scan.hpp"

#include "densemap/io/scan.hpp"

namespace densemap {

CorrectedPose toCorrectedPose(std::int64_t stamp_ns, const Transform& T_world_sensor) {
  const Eigen::Vector3d t = T_world_sensor.translation();
  const Eigen::Quaterniond q(T_world_sensor.linear());
  return {stamp_ns, {t.x(), t.y(), t.z()}, {q.w(), q.x(), q.y(), q.z()}};
}

RawScan toRawScan(const Scan& scan, std::uint64_t seq, const std::string& sensor_id) {
  RawScan raw;
  raw.sensor_id = sensor_id;
  raw.seq = seq;
  raw.stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::system_clock::now().time_since_epoch())
                     .count();
  const CorrectedPose pose = toCorrectedPose(raw.stamp_ns, scan.T_world_sensor);
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
