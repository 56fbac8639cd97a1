#pragma once

// What a ROS 2 recording holds, whatever its storage (MCAP, rosbag2's SQLite .db3): topics
// with their types and serialization, and messages by topic and time, read one at a time.
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap::ros2 {

struct BagChannel {
  std::uint16_t id = 0;
  std::string topic, message_encoding;       // "cdr" for ROS 2's messages
  std::string schema_name, schema_encoding;  // the type ("sensor_msgs/msg/PointCloud2")
};

/// Where a message's data lies: for MCAP in the file (chunk < 0) or in chunk `chunk`'s
/// records; for .db3 its row (offset).
struct BagMessage {
  std::uint16_t channel = 0;
  std::uint64_t log_time = 0;
  std::int64_t chunk = -1;
  std::uint64_t offset = 0, length = 0;
};

class BagReader {
 public:
  virtual ~BagReader() = default;
  [[nodiscard]] const std::vector<BagChannel>& channels() const { return channels_; }
  /// The channel with `id`, or null (looked up for every message: a hash, not a walk).
  [[nodiscard]] const BagChannel* channel(std::uint16_t id) const {
    const auto it = channel_at_.find(id);
    return it == channel_at_.end() ? nullptr : &channels_[it->second];
  }
  [[nodiscard]] const std::vector<BagMessage>& messages() const { return messages_; }
  /// A message's data, or at most its first `max_bytes` (thread-safe).
  [[nodiscard]] virtual Expected<std::string> data(const BagMessage& m,
                                                   std::uint64_t max_bytes = ~std::uint64_t{
                                                       0}) const = 0;
  /// Empty, or why the recording ends early.
  [[nodiscard]] const std::string& truncated() const { return truncated_; }
  [[nodiscard]] const std::string& name() const { return name_; }
  /// "MCAP bag", "rosbag2 SQLite bag".
  [[nodiscard]] virtual std::string kind() const = 0;

 protected:
  /// Adds a channel (the first one of an id counts; a repeated id is ignored).
  void addChannel(BagChannel c) {
    if (channel_at_.emplace(c.id, channels_.size()).second) channels_.push_back(std::move(c));
  }
  std::vector<BagMessage> messages_;
  std::string truncated_, name_;

 private:
  std::vector<BagChannel> channels_;
  std::unordered_map<std::uint16_t, std::size_t> channel_at_;
};

}  // namespace densemap::ros2
