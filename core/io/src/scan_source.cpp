#include "densemap/io/scan_source.hpp"

#include "densemap/io/file_bytes.hpp"

namespace densemap {
namespace {

Expected<std::unique_ptr<ScanSource>> inMemory(Expected<std::vector<Scan>> scans,
                                               const std::string& description) {
  if (!scans) return std::unexpected(scans.error());
  return std::make_unique<MemoryScanSource>(std::move(*scans), description);
}

bool endsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

Expected<std::unique_ptr<ScanSource>> openScanSource(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    if (std::filesystem::is_directory(path / "scans")) return openDatasetDirectory(path);
    if (std::filesystem::is_directory(path / "clouds_world")) return openWorldCloudDirectory(path);
    auto pcds = openPcdDirectory(path);
    if (pcds) return pcds;
    return fileError(path,
                     "not a dataset: expected scans/ + poses.txt, clouds_world/ + "
                     "sensor_poses_kitti.txt, or .pcd files");
  }
  if (!std::filesystem::exists(path, ec)) return fileError(path, "does not exist");
  const std::string name = path.filename().string();
  if (endsWith(name, ".graph")) return inMemory(readScanGraph(path), "ScanGraph " + path.string());
  if (endsWith(name, ".dat") || endsWith(name, ".dat.bz2") || endsWith(name, ".txt") ||
      endsWith(name, ".txt.bz2")) {
    return inMemory(readScanDat(path), "scan text " + path.string());
  }
  if (endsWith(name, ".pcd")) {
    auto scan = readPcd(path);
    if (!scan) return std::unexpected(scan.error());
    std::vector<Scan> one;
    one.push_back(std::move(*scan));
    return inMemory(std::move(one), "PCD " + path.string());
  }
  return fileError(path, "unknown dataset format (expected a directory, .graph, .pcd, .dat[.bz2])");
}

}  // namespace densemap
