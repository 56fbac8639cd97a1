#include "replies.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>

namespace densemap::server {

namespace {

// How long a reply waits for its writer to match the asker's reply reader (discovery of a new
// client usually completes within milliseconds on loopback).
constexpr std::chrono::milliseconds kAskerWait{2000};
// Participants tracked for the asker wait (beyond it, entries past their wait are dropped).
constexpr std::size_t kMaxAskersTracked = 4096;
// Reply writers kept (one per client and reply topic; the least recently used beyond go).
constexpr std::size_t kMaxReplyWriters = 1024;

}  // namespace

std::shared_ptr<const dds::Entity> ReplyWriters::writer(ReplyTopic topic, std::uint64_t client_id) {
  std::lock_guard lock(writers_mutex_);
  const auto key = std::pair(client_id, static_cast<int>(topic));
  if (auto it = writers_.find(key); it != writers_.end()) {
    it->second.last_used = ++uses_;
    return it->second.writer;
  }
  if (writers_.size() >= kMaxReplyWriters) {  // the least recently used goes
    auto oldest = writers_.begin();
    for (auto it = writers_.begin(); it != writers_.end(); ++it) {
      if (it->second.last_used < oldest->second.last_used) oldest = it;
    }
    writers_.erase(oldest);
  }
  const std::string partition = dds::replyPartition(client_id);
  dds::QosSpec qos = topic == ReplyTopic::kCommand ? dds::kCommandQos : dds::kRequestQos;
  qos.partition = partition;
  const dds::Entity& reply_topic = [&]() -> const dds::Entity& {
    switch (topic) {
      case ReplyTopic::kPoint:
        return topics_.point_reply;
      case ReplyTopic::kBbox:
        return topics_.bbox_reply;
      case ReplyTopic::kRay:
        return topics_.ray_reply;
      case ReplyTopic::kDistance:
        return topics_.distance_reply;
      case ReplyTopic::kPath:
        return topics_.path_reply;
      case ReplyTopic::kBoxes:
        return topics_.boxes_reply;
      case ReplyTopic::kDistanceBox:
        return topics_.distance_box_reply;
      case ReplyTopic::kCommand:
        break;
    }
    return topics_.command_reply;
  }();
  auto w = dds::createWriter(participant_, reply_topic, qos);
  if (!w) {
    // The request goes unanswered (its client times out): said in the log.
    spdlog::warn("no reply writer for client {:016x}: {}", client_id, w.error().message);
    return nullptr;
  }
  auto writer = std::make_shared<const dds::Entity>(std::move(*w));
  writers_[key] = {writer, ++uses_};
  return writer;
}

void ReplyWriters::awaitAsker(const dds::Entity& writer, const std::optional<dds_guid_t>& asker) {
  if (!asker) return;
  const std::string who(reinterpret_cast<const char*>(asker->v), sizeof asker->v);
  const std::string pair = std::to_string(writer.get()) + ":" + who;
  std::chrono::steady_clock::duration left{};
  {
    // Seen matched before: no lookup (the matched list is O(clients) per reply). Else the wait
    // is what is left of kAskerWait since this participant's first request, so a participant
    // that never creates a reply reader holds a query thread once, not once per request.
    std::lock_guard lock(askers_mutex_);
    if (askers_matched_.contains(pair)) return;
    const auto now = std::chrono::steady_clock::now();
    if (asker_first_seen_.size() > kMaxAskersTracked) {
      std::erase_if(asker_first_seen_, [&](const auto& e) { return now - e.second > kAskerWait; });
    }
    const auto first = asker_first_seen_.try_emplace(who, now).first->second;
    left = std::max(std::chrono::steady_clock::duration::zero(), kAskerWait - (now - first));
  }
  if (!dds::waitForReaderOf(writer, *asker,
                            std::chrono::duration_cast<std::chrono::milliseconds>(left))) {
    spdlog::debug("a reply goes out before its asker's reader matched");
    return;
  }
  std::lock_guard lock(askers_mutex_);
  if (askers_matched_.size() > kMaxAskersTracked) askers_matched_.clear();  // a cache only
  askers_matched_.insert(pair);
}

}  // namespace densemap::server
