#include "densemap/ros2/point_cloud2.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <optional>

namespace densemap::ros2 {
namespace {

const PointFieldView* findField(std::span<const PointFieldView> fields, std::string_view name) {
  for (const PointFieldView& f : fields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

/// One element of `type` at `p` as double, swapping bytes for big-endian data.
double readElement(const std::uint8_t* p, std::uint8_t type, bool swap) {
  std::uint8_t raw[8];
  const std::size_t n = pointFieldSize(type);
  std::memcpy(raw, p, n);
  if (swap) std::reverse(raw, raw + n);
  switch (static_cast<PointFieldType>(type)) {
    case PointFieldType::kInt8: {
      std::int8_t v;
      std::memcpy(&v, raw, 1);
      return v;
    }
    case PointFieldType::kUint8:
      return raw[0];
    case PointFieldType::kInt16: {
      std::int16_t v;
      std::memcpy(&v, raw, 2);
      return v;
    }
    case PointFieldType::kUint16: {
      std::uint16_t v;
      std::memcpy(&v, raw, 2);
      return v;
    }
    case PointFieldType::kInt32: {
      std::int32_t v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case PointFieldType::kUint32: {
      std::uint32_t v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case PointFieldType::kFloat32: {
      float v;
      std::memcpy(&v, raw, 4);
      return v;
    }
    case PointFieldType::kFloat64: {
      double v;
      std::memcpy(&v, raw, 8);
      return v;
    }
  }
  return 0.0;
}

bool fitsInPoint(const PointFieldView& f, std::uint32_t point_step) {
  const std::uint64_t end = std::uint64_t{f.offset} + pointFieldSize(f.datatype);
  return f.count >= 1 && end <= point_step;
}

}  // namespace

std::size_t pointFieldSize(std::uint8_t datatype) {
  switch (static_cast<PointFieldType>(datatype)) {
    case PointFieldType::kInt8:
    case PointFieldType::kUint8:
      return 1;
    case PointFieldType::kInt16:
    case PointFieldType::kUint16:
      return 2;
    case PointFieldType::kInt32:
    case PointFieldType::kUint32:
    case PointFieldType::kFloat32:
      return 4;
    case PointFieldType::kFloat64:
      return 8;
  }
  return 0;
}

std::string_view cloudRejectName(CloudReject reason) {
  switch (reason) {
    case CloudReject::kEmpty:
      return "empty cloud";
    case CloudReject::kMissingXyz:
      return "no x, y or z field";
    case CloudReject::kUnsupportedXyz:
      return "x/y/z not float32 or float64";
    case CloudReject::kFieldPastPoint:
      return "field beyond point_step";
    case CloudReject::kRowTooShort:
      return "row_step < width * point_step";
    case CloudReject::kDataTooShort:
      return "data shorter than row_step * height";
    case CloudReject::kTooManyPoints:
      return "too many points";
    case CloudReject::kCount:
      break;
  }
  return "unknown";
}

std::expected<DecodedCloud, CloudReject> decodePointCloud2(const PointCloud2View& cloud,
                                                           std::size_t max_points) {
  const std::uint64_t n = std::uint64_t{cloud.width} * cloud.height;  // no overflow in 64 bits
  if (n == 0) return std::unexpected(CloudReject::kEmpty);
  if (n > max_points) return std::unexpected(CloudReject::kTooManyPoints);
  const PointFieldView* axes[3] = {findField(cloud.fields, "x"), findField(cloud.fields, "y"),
                                   findField(cloud.fields, "z")};
  for (const PointFieldView* f : axes) {
    if (f == nullptr) return std::unexpected(CloudReject::kMissingXyz);
    if (f->datatype != static_cast<std::uint8_t>(PointFieldType::kFloat32) &&
        f->datatype != static_cast<std::uint8_t>(PointFieldType::kFloat64)) {
      return std::unexpected(CloudReject::kUnsupportedXyz);
    }
    if (!fitsInPoint(*f, cloud.point_step)) return std::unexpected(CloudReject::kFieldPastPoint);
  }
  const PointFieldView* intensity = findField(cloud.fields, "intensity");
  if (intensity != nullptr && pointFieldSize(intensity->datatype) == 0) intensity = nullptr;
  if (intensity != nullptr && !fitsInPoint(*intensity, cloud.point_step)) {
    return std::unexpected(CloudReject::kFieldPastPoint);
  }
  if (std::uint64_t{cloud.row_step} < std::uint64_t{cloud.width} * cloud.point_step) {
    return std::unexpected(CloudReject::kRowTooShort);
  }
  if (cloud.data.size() < std::uint64_t{cloud.row_step} * cloud.height) {
    return std::unexpected(CloudReject::kDataTooShort);
  }
  // The host is little-endian (x86-64, arm64): swap big-endian data.
  const bool swap = cloud.is_bigendian != (std::endian::native == std::endian::big);
  const bool fast =
      !swap && axes[0]->datatype == static_cast<std::uint8_t>(PointFieldType::kFloat32) &&
      axes[1]->datatype == axes[0]->datatype && axes[2]->datatype == axes[0]->datatype;
  DecodedCloud out;
  out.xyz.reserve(3 * n);
  if (intensity != nullptr) out.intensity.reserve(n);
  for (std::uint32_t row = 0; row < cloud.height; ++row) {
    const std::uint8_t* row_data = cloud.data.data() + std::size_t{row} * cloud.row_step;
    for (std::uint32_t col = 0; col < cloud.width; ++col) {
      const std::uint8_t* p = row_data + std::size_t{col} * cloud.point_step;
      float v[3];
      for (int a = 0; a < 3; ++a) {
        if (fast) {
          std::memcpy(&v[a], p + axes[a]->offset, 4);
        } else {
          v[a] = static_cast<float>(readElement(p + axes[a]->offset, axes[a]->datatype, swap));
        }
      }
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
        ++out.non_finite;
        continue;
      }
      out.xyz.insert(out.xyz.end(), v, v + 3);
      if (intensity != nullptr) {
        out.intensity.push_back(
            static_cast<float>(readElement(p + intensity->offset, intensity->datatype, swap)));
      }
    }
  }
  return out;
}

}  // namespace densemap::ros2
