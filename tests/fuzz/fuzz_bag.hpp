#pragma once
// What the bag fuzzers do with a bag that opened: each message's CDR cloud (and its points) or
// transforms, as openRecording would.
#include <span>

#include "densemap/ros2/bag_reader.hpp"
#include "densemap/ros2/cdr.hpp"
#include "densemap/ros2/point_cloud2.hpp"

namespace densemap::fuzz {

inline void decodeEveryMessage(const ros2::BagReader& reader) {
  for (const ros2::BagMessage& m : reader.messages()) {
    auto bytes = reader.data(m);
    if (!bytes) continue;
    const std::span<const std::uint8_t> span(reinterpret_cast<const std::uint8_t*>(bytes->data()),
                                             bytes->size());
    if (auto cloud = ros2::decodeCdrPointCloud2(span)) {
      (void)ros2::decodePointCloud2(cloud->view(), 1 << 16);
    }
    (void)ros2::decodeCdrTfMessage(span);
    (void)ros2::decodeCdrCloudHeader(span);
  }
}

}  // namespace densemap::fuzz
