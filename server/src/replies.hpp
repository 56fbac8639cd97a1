#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "densemap/wire/dds.hpp"
#include "densemap/wire/topics.hpp"
#include "densemap/geometry/point_cloud.hpp"

namespace densemap::server {

/// Request status codes of the replies (densemap_msgs.idl: 0 ok, 1 invalid, 2 internal).
inline constexpr std::int32_t kOk = 0, kInvalid = 1, kInternal = 2;

/// A request's float[3] (the IDL's point) as a point.
[[nodiscard]] inline Point3f toPoint(const float (&v)[3]) { return {v[0], v[1], v[2]}; }

/// The reply topics.
enum class ReplyTopic { kPoint, kBbox, kRay, kCommand, kDistance, kPath, kBoxes, kDistanceBox };

/// Replies to one asker only: the writer of a reply topic for one client,
/// in that client's partition (dds::replyPartition), made at its first request on that topic,
/// the most recently used kept (a task holding one keeps it alive); and the wait for the
/// asker's reader to match before a reply goes out. Thread-safe.
class ReplyWriters {
 public:
  ReplyWriters(const dds::Entity& participant, const dds::Topics& topics)
      : participant_(participant), topics_(topics) {}

  /// The writer of `topic`'s replies to `client_id`; null when DDS refuses it (logged).
  std::shared_ptr<const dds::Entity> writer(ReplyTopic topic, std::uint64_t client_id);
  /// Waits until `writer` has matched a reader of `asker`, at most what is left of kAskerWait
  /// (replies.cpp) since the asker's first request.
  void awaitAsker(const dds::Entity& writer, const std::optional<dds_guid_t>& asker);

 private:
  struct Cached {
    std::shared_ptr<const dds::Entity> writer;
    std::uint64_t last_used = 0;
  };
  const dds::Entity& participant_;
  const dds::Topics& topics_;
  std::mutex writers_mutex_;
  std::map<std::pair<std::uint64_t, int>, Cached> writers_;  // (client, topic)
  std::uint64_t uses_ = 0;
  std::mutex askers_mutex_;
  std::unordered_set<std::string> askers_matched_;  // "writer:participant" seen matched
  std::unordered_map<std::string, std::chrono::steady_clock::time_point> asker_first_seen_;
};

}  // namespace densemap::server
