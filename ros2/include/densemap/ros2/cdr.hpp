#pragma once

// sensor_msgs/PointCloud2 and tf2_msgs/TFMessage in plain CDR (XCDR1, @final), as ROS 2 bags
// store them (MCAP message_encoding "cdr", rosbag2's serialized messages): decoded from
// untrusted bytes with every length and count bounded before use, and encoded for the bags
// densemap writes.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/ros2/tf_buffer.hpp"

namespace densemap::ros2 {

/// std_msgs/Header.
struct CdrHeader {
  std::int64_t stamp_ns = 0;
  std::string frame_id;
};

/// A PointCloud2 decoded from CDR: its header and its fields and data, owned (view() lends
/// them as decodePointCloud2 reads them).
struct CdrCloud {
  CdrHeader header;
  std::vector<std::string> field_names;
  std::vector<PointFieldView> fields;  // names point into field_names
  std::uint32_t height = 0, width = 0, point_step = 0, row_step = 0;
  bool is_bigendian = false, is_dense = true;
  std::vector<std::uint8_t> data;
  [[nodiscard]] PointCloud2View view() const;
};

/// One geometry_msgs/TransformStamped.
struct CdrTransform {
  CdrHeader header;  // parent frame and stamp
  std::string child_frame_id;
  TfSample sample;
};

/// Decoders: an error names what is wrong (a length past the end, a string over its bound...).
[[nodiscard]] Expected<CdrCloud> decodeCdrPointCloud2(std::span<const std::uint8_t> bytes);
/// A PointCloud2's header alone (its frame and stamp, without copying its points).
[[nodiscard]] Expected<CdrHeader> decodeCdrCloudHeader(std::span<const std::uint8_t> bytes);
[[nodiscard]] Expected<std::vector<CdrTransform>> decodeCdrTfMessage(
    std::span<const std::uint8_t> bytes);

/// Encoders (little-endian CDR with its 4-byte encapsulation header).
[[nodiscard]] std::string encodeCdrPointCloud2(const CdrHeader& header, std::span<const float> xyz);
[[nodiscard]] std::string encodeCdrTfMessage(std::span<const CdrTransform> transforms);
/// nav_msgs/OccupancyGrid of `grid` in the plane z = `z_m` (map_load_time: the header's stamp).
[[nodiscard]] std::string encodeCdrOccupancyGrid(const CdrHeader& header, const GridImage& grid,
                                                 double z_m);

/// The bounds the decoders keep (refused beyond): characters of a string, fields of a cloud,
/// transforms of a message.
inline constexpr std::size_t kCdrMaxString = 4096;
inline constexpr std::size_t kCdrMaxFields = 256;
inline constexpr std::size_t kCdrMaxTransforms = 65536;

}  // namespace densemap::ros2
