#include "densemap/ros2/cdr.hpp"

#include "densemap/geometry/stamp.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>

namespace densemap::ros2 {
namespace {

/// Reads plain CDR after its encapsulation header: alignment relative to the header's end,
/// byte order from it; every read checked against the end.
class CdrReader {
 public:
  explicit CdrReader(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}

  Expected<void> begin() {
    if (bytes_.size() < 4) return makeError("CDR: shorter than its 4-byte header");
    if (bytes_[0] != 0 || (bytes_[1] != 0 && bytes_[1] != 1)) {
      return makeError("CDR: not plain CDR (encapsulation " + std::to_string(bytes_[0]) + "," +
                       std::to_string(bytes_[1]) + ")");
    }
    swap_ = (bytes_[1] == 1) != (std::endian::native == std::endian::little);
    base_ = pos_ = 4;
    return {};
  }
  template <class T>
  Expected<T> read() {
    if (auto ok = align(sizeof(T)); !ok) return std::unexpected(ok.error());
    if (bytes_.size() - pos_ < sizeof(T)) return makeError("CDR: ends inside a value");
    std::uint8_t raw[sizeof(T)];
    std::memcpy(raw, bytes_.data() + pos_, sizeof(T));
    if (swap_) std::reverse(raw, raw + sizeof(T));
    pos_ += sizeof(T);
    T v;
    std::memcpy(&v, raw, sizeof(T));
    return v;
  }
  Expected<std::string> string(std::string_view what) {
    auto n = read<std::uint32_t>();
    if (!n) return std::unexpected(n.error());
    // The length counts the terminating NUL; 0 is accepted as the empty string.
    if (*n > kCdrMaxString + 1) {
      return makeError("CDR: " + std::string(what) + " longer than " +
                       std::to_string(kCdrMaxString) + " characters");
    }
    if (bytes_.size() - pos_ < *n) return makeError("CDR: " + std::string(what) + " past the end");
    std::string s(reinterpret_cast<const char*>(bytes_.data() + pos_), *n);
    pos_ += *n;
    while (!s.empty() && s.back() == '\0') s.pop_back();
    if (s.find('\0') != std::string::npos) {
      return makeError("CDR: " + std::string(what) + " holds a NUL");
    }
    return s;
  }
  /// A sequence's count, checked against the bytes left for `min_element_bytes` each.
  Expected<std::uint32_t> count(std::string_view what, std::size_t max,
                                std::size_t min_element_bytes) {
    auto n = read<std::uint32_t>();
    if (!n) return std::unexpected(n.error());
    if (*n > max) {
      return makeError("CDR: " + std::to_string(*n) + " " + std::string(what) + " (at most " +
                       std::to_string(max) + ")");
    }
    if (std::uint64_t{*n} * min_element_bytes > bytes_.size() - pos_) {
      return makeError("CDR: " + std::string(what) + " past the end");
    }
    return *n;
  }
  Expected<std::span<const std::uint8_t>> octets(std::uint32_t n) {
    if (bytes_.size() - pos_ < n) return makeError("CDR: data past the end");
    auto s = bytes_.subspan(pos_, n);
    pos_ += n;
    return s;
  }

 private:
  Expected<void> align(std::size_t n) {
    const std::size_t offset = (pos_ - base_) % n;
    if (offset != 0) {
      if (bytes_.size() - pos_ < n - offset) return makeError("CDR: ends inside padding");
      pos_ += n - offset;
    }
    return {};
  }
  std::span<const std::uint8_t> bytes_;
  std::size_t base_ = 0, pos_ = 0;
  bool swap_ = false;
};

#define DENSEMAP_CDR_TRY(var, expr) \
  auto var = (expr);                \
  if (!var) return std::unexpected(var.error())

Expected<CdrHeader> readHeader(CdrReader& r) {
  DENSEMAP_CDR_TRY(sec, r.read<std::int32_t>());
  DENSEMAP_CDR_TRY(nanosec, r.read<std::uint32_t>());
  DENSEMAP_CDR_TRY(frame, r.string("frame_id"));
  if (*nanosec >= 1'000'000'000U) return makeError("CDR: header stamp nanosec >= 1e9");
  return CdrHeader{std::int64_t{*sec} * 1'000'000'000 + *nanosec, std::move(*frame)};
}

/// Little-endian CDR, aligned from after the header.
class CdrWriter {
 public:
  CdrWriter() { out_.append("\x00\x01\x00\x00", 4); }
  template <class T>
  void write(T v) {
    static_assert(std::endian::native == std::endian::little, "little-endian hosts only");
    while ((out_.size() - 4) % sizeof(T) != 0) out_.push_back('\0');
    out_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void string(const std::string& s) {
    write(static_cast<std::uint32_t>(s.size() + 1));
    out_.append(s);
    out_.push_back('\0');
  }
  /// builtin_interfaces/Time: seconds (floored) and nanoseconds in [0, 1e9).
  void time(std::int64_t ns) {
    const SplitStamp t = splitStamp(ns);
    write(static_cast<std::int32_t>(t.sec));
    write(t.nanosec);
  }
  void header(const CdrHeader& h) {
    time(h.stamp_ns);
    string(h.frame_id);
  }
  void bytes(const void* p, std::size_t n) { out_.append(static_cast<const char*>(p), n); }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

}  // namespace

PointCloud2View CdrCloud::view() const {
  return {height, width, fields, is_bigendian, point_step, row_step, data, is_dense};
}

Expected<CdrCloud> decodeCdrPointCloud2(std::span<const std::uint8_t> bytes) {
  CdrReader r(bytes);
  if (auto ok = r.begin(); !ok) return std::unexpected(ok.error());
  CdrCloud c;
  DENSEMAP_CDR_TRY(header, readHeader(r));
  c.header = std::move(*header);
  DENSEMAP_CDR_TRY(height, r.read<std::uint32_t>());
  DENSEMAP_CDR_TRY(width, r.read<std::uint32_t>());
  c.height = *height;
  c.width = *width;
  // A field: a string (4 + 1 bytes at least), offset, datatype, count.
  DENSEMAP_CDR_TRY(n_fields, r.count("point fields", kCdrMaxFields, 14));
  c.field_names.reserve(*n_fields);
  c.fields.reserve(*n_fields);
  for (std::uint32_t i = 0; i < *n_fields; ++i) {
    DENSEMAP_CDR_TRY(name, r.string("field name"));
    DENSEMAP_CDR_TRY(offset, r.read<std::uint32_t>());
    DENSEMAP_CDR_TRY(datatype, r.read<std::uint8_t>());
    DENSEMAP_CDR_TRY(count, r.read<std::uint32_t>());
    c.field_names.push_back(std::move(*name));
    c.fields.push_back({{}, *offset, *datatype, *count});
  }
  for (std::size_t i = 0; i < c.fields.size(); ++i) c.fields[i].name = c.field_names[i];
  DENSEMAP_CDR_TRY(big, r.read<std::uint8_t>());
  DENSEMAP_CDR_TRY(point_step, r.read<std::uint32_t>());
  DENSEMAP_CDR_TRY(row_step, r.read<std::uint32_t>());
  DENSEMAP_CDR_TRY(n_data, r.count("data bytes", bytes.size(), 1));
  DENSEMAP_CDR_TRY(data, r.octets(*n_data));
  DENSEMAP_CDR_TRY(dense, r.read<std::uint8_t>());
  c.is_bigendian = *big != 0;
  c.point_step = *point_step;
  c.row_step = *row_step;
  c.data.assign(data->begin(), data->end());
  c.is_dense = *dense != 0;
  return c;
}

Expected<CdrHeader> decodeCdrCloudHeader(std::span<const std::uint8_t> bytes) {
  CdrReader r(bytes);
  if (auto ok = r.begin(); !ok) return std::unexpected(ok.error());
  return readHeader(r);
}

Expected<std::vector<CdrTransform>> decodeCdrTfMessage(std::span<const std::uint8_t> bytes) {
  CdrReader r(bytes);
  if (auto ok = r.begin(); !ok) return std::unexpected(ok.error());
  // A transform: a header (8 + 4 + 1), a child name (4 + 1), 7 doubles.
  DENSEMAP_CDR_TRY(n, r.count("transforms", kCdrMaxTransforms, 74));
  std::vector<CdrTransform> out;
  out.reserve(*n);
  for (std::uint32_t i = 0; i < *n; ++i) {
    CdrTransform t;
    DENSEMAP_CDR_TRY(header, readHeader(r));
    t.header = std::move(*header);
    DENSEMAP_CDR_TRY(child, r.string("child_frame_id"));
    t.child_frame_id = std::move(*child);
    double v[7];
    for (double& x : v) {
      DENSEMAP_CDR_TRY(d, r.read<double>());
      x = *d;
    }
    t.sample.stamp_ns = t.header.stamp_ns;
    t.sample.t = Eigen::Vector3d(v[0], v[1], v[2]);
    t.sample.q = Eigen::Quaterniond(v[6], v[3], v[4], v[5]);  // x, y, z, w on the wire
    out.push_back(std::move(t));
  }
  return out;
}

std::string encodeCdrPointCloud2(const CdrHeader& header, std::span<const float> xyz) {
  CdrWriter w;
  w.header(header);
  const auto n = static_cast<std::uint32_t>(xyz.size() / 3);
  w.write(std::uint32_t{1});  // height
  w.write(n);                 // width
  w.write(std::uint32_t{3});
  const char* names[] = {"x", "y", "z"};
  for (std::uint32_t i = 0; i < 3; ++i) {
    w.string(names[i]);
    w.write(std::uint32_t{4 * i});
    w.write(static_cast<std::uint8_t>(PointFieldType::kFloat32));
    w.write(std::uint32_t{1});
  }
  w.write(std::uint8_t{0});    // is_bigendian
  w.write(std::uint32_t{12});  // point_step
  w.write(12 * n);             // row_step
  w.write(12 * n);
  w.bytes(xyz.data(), 12 * std::size_t{n});
  w.write(std::uint8_t{1});  // is_dense
  return w.take();
}

std::string encodeCdrTfMessage(std::span<const CdrTransform> transforms) {
  CdrWriter w;
  w.write(static_cast<std::uint32_t>(transforms.size()));
  for (const CdrTransform& t : transforms) {
    w.header(t.header);
    w.string(t.child_frame_id);
    const Eigen::Quaterniond& q = t.sample.q;
    for (double v : {t.sample.t.x(), t.sample.t.y(), t.sample.t.z(), q.x(), q.y(), q.z(), q.w()}) {
      w.write(v);
    }
  }
  return w.take();
}

std::string encodeCdrOccupancyGrid(const CdrHeader& header, const GridImage& grid, double z_m) {
  CdrWriter w;
  w.header(header);
  w.time(header.stamp_ns);  // map_load_time
  w.write(static_cast<float>(grid.resolution));
  w.write(grid.width);
  w.write(grid.height);
  for (double v : {grid.origin_x, grid.origin_y, z_m, 0.0, 0.0, 0.0, 1.0}) w.write(v);
  w.write(static_cast<std::uint32_t>(grid.data.size()));
  w.bytes(grid.data.data(), grid.data.size());
  return w.take();
}

}  // namespace densemap::ros2
