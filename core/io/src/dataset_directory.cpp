#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"
#include "kitti_format.hpp"

namespace densemap::kitti {

Expected<std::vector<Transform>> readPoses(const std::filesystem::path& file) {
  auto text = readFileBytes(file);
  if (!text) return std::unexpected(text.error());
  std::vector<Transform> poses;
  std::istringstream lines(*text);
  std::string line;
  int line_no = 0;
  while (std::getline(lines, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream fields(line);
    double v[12];
    for (int i = 0; i < 12; ++i) {
      if (!(fields >> v[i]) || !std::isfinite(v[i])) {
        return fileError(file, "line " + std::to_string(line_no) +
                                   ": expected 12 finite numbers (3x4 row-major pose)");
      }
    }
    std::string extra;
    if (fields >> extra) {
      return fileError(file, "line " + std::to_string(line_no) + ": more than 12 numbers");
    }
    const Transform pose = transformFromRows(v);
    if (auto ok = checkRigidPose(pose); !ok) {
      return fileError(file, "line " + std::to_string(line_no) + ": " + ok.error().message);
    }
    poses.push_back(pose);
  }
  if (poses.empty()) return fileError(file, "no poses");
  return poses;
}

Expected<void> readPoints(const std::filesystem::path& file, Scan& scan) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  if (bytes->size() % 16 != 0) {
    return fileError(file, "size " + std::to_string(bytes->size()) +
                               " bytes is not a multiple of 16 (float32 x y z intensity): "
                               "truncated or not a point file");
  }
  const std::size_t n = bytes->size() / 16;
  scan.points.resize(n);
  scan.intensities.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    float rec[4];
    std::memcpy(rec, bytes->data() + i * 16, 16);
    scan.points[i] = Point3f(rec[0], rec[1], rec[2]);
    scan.intensities[i] = rec[3];
  }
  return {};
}

Expected<std::map<std::size_t, std::filesystem::path>> listNumberedBins(
    const std::filesystem::path& dir) {
  std::map<std::size_t, std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.path().extension() != ".bin") continue;
    const std::string stem = entry.path().stem().string();
    std::size_t id = 0;
    const auto [ptr, err] = std::from_chars(stem.data(), stem.data() + stem.size(), id);
    if (err != std::errc() || ptr != stem.data() + stem.size()) continue;
    files.emplace(id, entry.path());
  }
  if (ec) return fileError(dir, "cannot list: " + ec.message());
  if (files.empty()) return fileError(dir, "no numbered .bin scan files");
  return files;
}

namespace {

class NumberedDirectory final : public ScanSource {
 public:
  NumberedDirectory(std::vector<std::pair<std::size_t, std::filesystem::path>> files,
                    std::vector<Transform> poses, PointFrame frame, std::string description)
      : files_(std::move(files)),
        poses_(std::move(poses)),
        frame_(frame),
        description_(std::move(description)) {}

  [[nodiscard]] std::size_t size() const override { return files_.size(); }
  [[nodiscard]] std::string describe() const override { return description_; }
  [[nodiscard]] Expected<Scan> load(std::size_t index) const override {
    if (index >= files_.size()) return makeError("scan index out of range");
    Scan scan;
    scan.id = files_[index].first;
    scan.frame = frame_;
    scan.T_world_sensor = poses_[scan.id];
    if (auto ok = readPoints(files_[index].second, scan); !ok) return std::unexpected(ok.error());
    return scan;
  }

 private:
  std::vector<std::pair<std::size_t, std::filesystem::path>> files_;
  std::vector<Transform> poses_;
  PointFrame frame_;
  std::string description_;
};

}  // namespace

Expected<std::unique_ptr<ScanSource>> openNumberedDirectory(const std::filesystem::path& scans_dir,
                                                            const std::filesystem::path& poses_file,
                                                            PointFrame frame,
                                                            const std::string& format_name) {
  auto files = listNumberedBins(scans_dir);
  if (!files) return std::unexpected(files.error());
  auto poses = readPoses(poses_file);
  if (!poses) return std::unexpected(poses.error());
  // Line i is the pose of scan number i (a directory may hold only some scans).
  const std::size_t last_id = files->rbegin()->first;
  if (last_id >= poses->size()) {
    return fileError(poses_file, "has " + std::to_string(poses->size()) + " poses but scan " +
                                     std::to_string(last_id) + " needs line " +
                                     std::to_string(last_id + 1));
  }
  std::vector<std::pair<std::size_t, std::filesystem::path>> ordered(files->begin(), files->end());
  const std::string description =
      format_name + " " + scans_dir.parent_path().string() + " (" + std::to_string(ordered.size()) +
      " scans, " + std::to_string(ordered.front().first) + ".." + std::to_string(last_id) + ")";
  return std::make_unique<NumberedDirectory>(std::move(ordered), std::move(*poses), frame,
                                             description);
}

}  // namespace densemap::kitti

namespace densemap {

Expected<std::unique_ptr<ScanSource>> openDatasetDirectory(const std::filesystem::path& dir) {
  std::filesystem::path poses = dir / "poses.txt";
  if (!std::filesystem::exists(poses)) poses = dir / "poses_kitti.txt";
  if (!std::filesystem::exists(poses)) {
    return fileError(dir, "dataset directory has no poses.txt or poses_kitti.txt");
  }
  return kitti::openNumberedDirectory(dir / "scans", poses, PointFrame::kSensor, "dataset");
}

Expected<std::unique_ptr<ScanSource>> openWorldCloudDirectory(const std::filesystem::path& dir) {
  return kitti::openNumberedDirectory(dir / "clouds_world", dir / "sensor_poses_kitti.txt",
                                      PointFrame::kWorld, "world-frame clouds");
}

Expected<Scan> MemoryScanSource::load(std::size_t index) const {
  if (index >= scans_.size()) return makeError("scan index out of range");
  return scans_[index];
}

}  // namespace densemap
