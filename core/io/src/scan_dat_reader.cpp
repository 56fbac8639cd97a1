#include <octomap/math/Pose6D.h>

#include <cmath>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/text_lines.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {

// OctoMap's plain-text scan format (`ScanGraph::readPlainASCII`, what log2graph reads): "NODE x
// y z roll pitch yaw" starts a scan at that pose; other lines are "x y z" points in that scan's
// sensor frame. As OctoMap does: numbers are read as float, the pose is OctoMap's float pose6d,
// and lines that start with '#' or a space are skipped. Unlike OctoMap, a file without NODE
// lines is one scan taken at the origin, and a malformed line is an error. The text is read a
// line at a time (TextLines): memory holds the scans' points, never the file.
Expected<std::vector<Scan>> readScanDat(const std::filesystem::path& file) {
  auto lines = TextLines::open(file);
  if (!lines) return std::unexpected(lines.error());
  std::vector<Scan> scans;
  for (;;) {
    auto next = lines->next();
    if (!next) return std::unexpected(next.error());
    if (!*next) break;
    const std::string& line = **next;
    const std::uint64_t line_no = lines->lineNumber();
    if (line.empty() || line[0] == '#' || line[0] == ' ' ||
        line.find_first_not_of(" \t\r") == std::string::npos) {
      continue;
    }
    std::istringstream in(line);
    auto bad = [&](const std::string& what) {
      return fileError(file, "line " + std::to_string(line_no) + ": " + what);
    };
    if (line.rfind("NODE", 0) == 0) {
      std::string tag;
      float v[6];
      in >> tag;
      for (float& x : v) {
        if (!(in >> x) || !std::isfinite(x)) return bad("NODE needs x y z roll pitch yaw");
      }
      const octomath::Pose6D pose(v[0], v[1], v[2], v[3], v[4], v[5]);
      Scan scan;
      scan.id = scans.size();
      scan.octomap_pose =
          OctomapPose{{pose.x(), pose.y(), pose.z()},
                      {pose.rot().u(), pose.rot().x(), pose.rot().y(), pose.rot().z()}};
      scan.T_world_sensor = transformFromOctomapPose(*scan.octomap_pose);
      scans.push_back(std::move(scan));
      continue;
    }
    float x, y, z;
    if (!(in >> x >> y >> z)) return bad("expected 'x y z' or a NODE line");
    if (scans.empty()) {
      scans.emplace_back();
      scans.back().octomap_pose = OctomapPose{};
    }
    scans.back().points.emplace_back(x, y, z);
  }
  if (scans.empty()) return fileError(file, "no points");
  return scans;
}

}  // namespace densemap
