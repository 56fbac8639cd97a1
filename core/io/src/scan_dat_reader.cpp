#include <cmath>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {

// OctoMap's plain-text scan format (`ScanGraph::readPlainASCII`): "NODE x y z roll pitch yaw"
// starts a scan at that pose; other lines are "x y z" points in that scan's sensor frame. A
// file without NODE lines is one scan taken at the origin (OctoMap's example scan.dat).
Expected<std::vector<Scan>> readScanDat(const std::filesystem::path& file) {
  auto text = readFileBytes(file);
  if (!text) return std::unexpected(text.error());
  std::vector<Scan> scans;
  std::istringstream lines(*text);
  std::string line;
  std::size_t line_no = 0;
  while (std::getline(lines, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos || line[0] == '#') continue;
    std::istringstream in(line);
    auto bad = [&](const std::string& what) {
      return fileError(file, "line " + std::to_string(line_no) + ": " + what);
    };
    if (line.rfind("NODE", 0) == 0) {
      std::string tag;
      double v[6];
      in >> tag;
      for (double& x : v) {
        if (!(in >> x) || !std::isfinite(x)) return bad("NODE needs x y z roll pitch yaw");
      }
      Scan scan;
      scan.id = scans.size();
      scan.T_world_sensor = Transform::Identity();
      scan.T_world_sensor.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
      scan.T_world_sensor.linear() = (Eigen::AngleAxisd(v[5], Eigen::Vector3d::UnitZ()) *
                                      Eigen::AngleAxisd(v[4], Eigen::Vector3d::UnitY()) *
                                      Eigen::AngleAxisd(v[3], Eigen::Vector3d::UnitX()))
                                         .toRotationMatrix();
      scans.push_back(std::move(scan));
      continue;
    }
    double x, y, z;
    if (!(in >> x >> y >> z)) return bad("expected 'x y z' or a NODE line");
    if (scans.empty()) scans.emplace_back();
    scans.back().points.emplace_back(static_cast<float>(x), static_cast<float>(y),
                                     static_cast<float>(z));
  }
  if (scans.empty()) return fileError(file, "no points");
  return scans;
}

}  // namespace densemap
