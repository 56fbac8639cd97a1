// A ROS 2 MCAP bag as a user's recording arrives: the container (records, chunks, their
// compression and CRC), then each message's CDR PointCloud2 or TFMessage, then the points.
#include <string>

#include "densemap/ros2/mcap.hpp"
#include "fuzz_bag.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  densemap::ros2::McapLimits limits;
  limits.max_chunk_bytes = std::size_t{4} << 20;
  limits.max_messages = 4096;
  auto reader = densemap::ros2::McapReader::fromBytes(
      std::string(reinterpret_cast<const char*>(data), size), limits);
  if (!reader) return 0;
  densemap::fuzz::decodeEveryMessage(**reader);
  return 0;
}
