// A ROS 2 MCAP bag as a user's recording arrives: the container (records, chunks, their
// compression and CRC), then each message's CDR PointCloud2 or TFMessage, then the points.
#include <string>

#include "densemap/ros2/cdr.hpp"
#include "densemap/ros2/mcap.hpp"
#include "densemap/ros2/point_cloud2.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::ros2::McapLimits limits;
  limits.max_chunk_bytes = std::size_t{4} << 20;
  limits.max_messages = 4096;
  auto reader = densemap::ros2::McapReader::fromBytes(
      std::string(reinterpret_cast<const char*>(data), size), limits);
  if (!reader) return 0;
  for (const densemap::ros2::BagMessage& m : (*reader)->messages()) {
    auto bytes = (*reader)->data(m);
    if (!bytes) continue;
    const std::span<const std::uint8_t> span(reinterpret_cast<const std::uint8_t*>(bytes->data()),
                                             bytes->size());
    if (auto cloud = densemap::ros2::decodeCdrPointCloud2(span)) {
      (void)densemap::ros2::decodePointCloud2(cloud->view(), 1 << 16);
    }
    (void)densemap::ros2::decodeCdrTfMessage(span);
    (void)densemap::ros2::decodeCdrCloudHeader(span);
  }
  return 0;
}
