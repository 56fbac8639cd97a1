#include <cmath>
#include <cstring>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {
namespace {

/// Bounds-checked little-endian reader over a byte buffer.
class ByteReader {
 public:
  explicit ByteReader(const std::string& bytes) : bytes_(bytes) {}
  template <class T>
  bool read(T& out) {
    if (pos_ + sizeof(T) > bytes_.size()) return false;
    std::memcpy(&out, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return true;
  }
  [[nodiscard]] std::size_t remaining() const { return bytes_.size() - pos_; }
  [[nodiscard]] std::size_t position() const { return pos_; }

 private:
  const std::string& bytes_;
  std::size_t pos_ = 0;
};

// OctoMap's Vector3/Quaternion::readBinary: an int32 element count, then that many doubles.
bool readDoubles(ByteReader& in, int expected_count, double* out) {
  std::int32_t count = 0;
  if (!in.read(count) || count != expected_count) return false;
  for (int i = 0; i < expected_count; ++i) {
    if (!in.read(out[i])) return false;
  }
  return true;
}

}  // namespace

Expected<std::vector<Scan>> readScanGraph(const std::filesystem::path& file) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  ByteReader in(*bytes);
  std::uint32_t n_nodes = 0;
  if (!in.read(n_nodes)) return fileError(file, "empty ScanGraph file");
  // Each node needs at least 4 (count) + 2 * 28 (pose) + 4 (id) bytes: reject absurd counts
  // before reserving memory for them.
  if (n_nodes > in.remaining() / 64) {
    return fileError(file, "ScanGraph claims " + std::to_string(n_nodes) +
                               " nodes, more than the file can hold");
  }
  std::vector<Scan> scans;
  scans.reserve(n_nodes);
  for (std::uint32_t node = 0; node < n_nodes; ++node) {
    auto broken = [&](const std::string& what) {
      return fileError(file, "ScanGraph node " + std::to_string(node) + ": " + what + " at byte " +
                                 std::to_string(in.position()) +
                                 " (truncated or not a .graph file)");
    };
    std::uint32_t n_points = 0;
    if (!in.read(n_points)) return broken("missing point count");
    if (n_points > in.remaining() / 28) return broken("point count larger than the file");
    Scan scan;
    scan.frame = PointFrame::kSensor;
    scan.points.reserve(n_points);
    for (std::uint32_t i = 0; i < n_points; ++i) {
      double p[3];
      if (!readDoubles(in, 3, p)) return broken("bad point " + std::to_string(i));
      // Vector3::readBinary stores the doubles as float.
      scan.points.emplace_back(static_cast<float>(p[0]), static_cast<float>(p[1]),
                               static_cast<float>(p[2]));
    }
    double t[3], q[4];
    if (!readDoubles(in, 3, t)) return broken("bad pose translation");
    if (!readDoubles(in, 4, q)) return broken("bad pose rotation");
    const double q_norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!std::isfinite(q_norm) || q_norm < 1e-6) return broken("degenerate pose quaternion");
    // Pose6D::readBinary stores the doubles as float too.
    scan.octomap_pose =
        OctomapPose{{static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2])},
                    {static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2]),
                     static_cast<float>(q[3])}};
    scan.T_world_sensor = transformFromOctomapPose(*scan.octomap_pose);
    if (auto ok = checkRigidPose(scan.T_world_sensor); !ok) {
      return broken("node " + std::to_string(scans.size()) + ": " + ok.error().message);
    }
    std::uint32_t id = 0;
    if (!in.read(id)) return broken("missing node id");
    scan.id = id;
    scans.push_back(std::move(scan));
  }
  // Edges follow (uint32 count, then edges); densemap does not use them.
  return scans;
}

}  // namespace densemap
