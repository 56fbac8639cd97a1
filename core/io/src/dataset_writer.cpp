#include "densemap/io/dataset_writer.hpp"

#include <cstdio>
#include <cstring>
#include <sstream>

#include "densemap/io/file_bytes.hpp"

namespace densemap {

Expected<DatasetWriter> DatasetWriter::create(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir / "scans", ec);
  if (ec) return fileError(dir, "cannot create dataset directory: " + ec.message());
  return DatasetWriter(dir);
}

Expected<void> DatasetWriter::write(const Scan& scan) {
  const PointCloud points = scan.frame == PointFrame::kSensor
                                ? scan.points
                                : transformPoints(scan.T_world_sensor.inverse(), scan.points);
  std::string bytes(points.size() * 16, '\0');
  for (std::size_t i = 0; i < points.size(); ++i) {
    const float rec[4] = {points[i].x(), points[i].y(), points[i].z(),
                          i < scan.intensities.size() ? scan.intensities[i] : 0.0F};
    std::memcpy(bytes.data() + i * 16, rec, 16);
  }
  char name[32];
  std::snprintf(name, sizeof(name), "%06zu.bin", scan.id);
  if (auto ok = writeFileAtomically(dir_ / "scans" / name, bytes); !ok) return ok;
  poses_[scan.id] = scan.T_world_sensor;
  return {};
}

Expected<void> DatasetWriter::finish() {
  if (poses_.empty()) return fileError(dir_, "no scans written");
  std::ostringstream out;
  out.precision(17);
  const std::size_t last = poses_.rbegin()->first;
  for (std::size_t id = 0; id <= last; ++id) {
    const auto it = poses_.find(id);
    const Transform T = it == poses_.end() ? Transform::Identity() : it->second;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) out << T.matrix()(r, c) << (r == 2 && c == 3 ? '\n' : ' ');
    }
  }
  return writeFileAtomically(dir_ / "poses.txt", out.str());
}

}  // namespace densemap
