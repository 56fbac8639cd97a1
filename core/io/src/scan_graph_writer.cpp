#include <Eigen/Geometry>

#include <cstdint>
#include <cstring>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {
namespace {

template <class T>
void put(std::string& out, T value) {
  char raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  out.append(raw, sizeof(T));
}

// OctoMap's Vector3/Quaternion::writeBinary: an int32 element count, then the floats as doubles.
template <std::size_t N>
void putFloats(std::string& out, const std::array<float, N>& values) {
  put<std::int32_t>(out, static_cast<std::int32_t>(N));
  for (float v : values) put<double>(out, v);
}

/// The pose a node gets: OctoMap's own if the scan came from OctoMap, else the double pose
/// rounded to float; world-frame scans are stored relative to their origin, unrotated.
OctomapPose nodePose(const Scan& scan) {
  if (scan.frame == PointFrame::kWorld) {
    const Point3f o = scan.originWorld();
    return {{o.x(), o.y(), o.z()}, {1, 0, 0, 0}};
  }
  if (scan.octomap_pose) return *scan.octomap_pose;
  const Eigen::Vector3d t = scan.T_world_sensor.translation();
  const Eigen::Quaterniond q(scan.T_world_sensor.linear());
  return {{static_cast<float>(t.x()), static_cast<float>(t.y()), static_cast<float>(t.z())},
          {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
           static_cast<float>(q.z())}};
}

}  // namespace

Expected<void> writeScanGraph(const ScanSource& source, std::size_t first, std::size_t count,
                              const std::filesystem::path& file,
                              const std::function<void(std::size_t)>& progress) {
  if (first >= source.size() && source.size() > 0) {
    return fileError(file, "first scan " + std::to_string(first) + " is past the " +
                               std::to_string(source.size()) + " scans of " + source.describe());
  }
  const std::size_t n = std::min(count, source.size() - std::min(first, source.size()));
  if (n > UINT32_MAX) return fileError(file, "too many scans for a ScanGraph");
  std::string out;
  put<std::uint32_t>(out, static_cast<std::uint32_t>(n));
  for (std::size_t i = 0; i < n; ++i) {
    auto scan = source.load(first + i);
    if (!scan) return std::unexpected(scan.error());
    if (scan->points.size() > UINT32_MAX) return fileError(file, "scan too large for a ScanGraph");
    const OctomapPose pose = nodePose(*scan);
    put<std::uint32_t>(out, static_cast<std::uint32_t>(scan->points.size()));
    for (const Point3f& p : scan->points) {
      const Point3f local = scan->frame == PointFrame::kWorld
                                ? Point3f(p.x() - pose.t[0], p.y() - pose.t[1], p.z() - pose.t[2])
                                : p;
      putFloats<3>(out, {local.x(), local.y(), local.z()});
    }
    putFloats<3>(out, pose.t);
    putFloats<4>(out, pose.q);
    put<std::uint32_t>(out, static_cast<std::uint32_t>(i));
    if (progress) progress(i + 1);
  }
  put<std::uint32_t>(out, 0);  // no edges
  return writeFileAtomically(file, out);
}

}  // namespace densemap
