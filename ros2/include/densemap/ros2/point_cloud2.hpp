#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string_view>
#include <vector>

namespace densemap::ros2 {

/// sensor_msgs/msg/PointField datatype constants (not on the wire; from PointField.msg).
enum class PointFieldType : std::uint8_t {
  kInt8 = 1,
  kUint8 = 2,
  kInt16 = 3,
  kUint16 = 4,
  kInt32 = 5,
  kUint32 = 6,
  kFloat32 = 7,
  kFloat64 = 8,
};
/// Bytes of one element of `datatype`, 0 for an unknown type.
[[nodiscard]] std::size_t pointFieldSize(std::uint8_t datatype);

struct PointFieldView {
  std::string_view name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;
  std::uint32_t count = 1;
};

/// A sensor_msgs/msg/PointCloud2 as received (header aside), borrowed from the DDS sample.
struct PointCloud2View {
  std::uint32_t height = 0;
  std::uint32_t width = 0;
  std::span<const PointFieldView> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0;
  std::uint32_t row_step = 0;
  std::span<const std::uint8_t> data;
  bool is_dense = true;
};

/// Why a cloud was refused (counted per reason by the server).
enum class CloudReject {
  kEmpty,           // width * height == 0
  kMissingXyz,      // no x, y or z field
  kUnsupportedXyz,  // x/y/z not float32 or float64
  kFieldPastPoint,  // a used field ends beyond point_step
  kRowTooShort,     // row_step < width * point_step
  kDataTooShort,    // data shorter than row_step * height
  kTooManyPoints,   // width * height above the server's limit (or overflowing)
  kCount
};
inline constexpr std::size_t kCloudRejectCount = static_cast<std::size_t>(CloudReject::kCount);
[[nodiscard]] std::string_view cloudRejectName(CloudReject reason);

struct DecodedCloud {
  std::vector<float> xyz;        // 3 per kept point
  std::vector<float> intensity;  // empty, or one per kept point (field "intensity")
  std::size_t non_finite = 0;    // points dropped for a NaN/Inf coordinate (is_dense false)
};

/// Reads the points of any field layout with x, y, z as float32 or float64 (little- or
/// big-endian; organized or not; padding anywhere), and an optional "intensity" of any numeric
/// type. Never reads outside `data`: every size is checked first, in 64-bit arithmetic.
[[nodiscard]] std::expected<DecodedCloud, CloudReject> decodePointCloud2(
    const PointCloud2View& cloud, std::size_t max_points);

}  // namespace densemap::ros2
