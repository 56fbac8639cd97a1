#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <memory>
#include <mutex>

#include "densemap/wire/dds.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/server/ros2_bridge.hpp"
#include "foxglove_room.hpp"

namespace densemap::server {

/// What goes out per map version: a map/events sample (on the pipeline's worker, small), then
/// on the publish thread a map/delta (only while a reader is matched; diffed from the versions'
/// written blocks, never the whole map; a backlog coalesced), and the manifest at 1 Hz.
class Publisher {
 public:
  struct Writers {
    const dds::Entity& events;
    const dds::Entity& deltas;
    const dds::Entity& manifest;
  };
  /// The map loaded at start (a snapshot) is the first delta's base.
  Publisher(Ingest& ingest, Writers writers, Ros2Bridge* ros2, FoxgloveRoom* foxglove)
      : ingest_(ingest),
        writers_(writers),
        ros2_(ros2),
        foxglove_(foxglove),
        delta_base_(ingest.view()) {}

  /// The pipeline's publisher (its worker): the event now, the version to the publish thread.
  void onIntegrated(const IntegrationResult& result, const std::shared_ptr<const MapView>& view);
  /// Publish thread: waits until a version arrives, `until`, or wake() (with `running` false),
  /// then publishes the deltas of the versions waiting.
  void publishWaiting(std::chrono::steady_clock::time_point until,
                      const std::atomic<bool>& running);
  void wake() { cv_.notify_all(); }
  /// Publish thread: the manifest (what a fetch would get), at 1 Hz.
  void publishManifest();

 private:
  struct Version {  // a published version handed to the publish thread
    IntegrationResult result;
    std::shared_ptr<const MapView> view;
  };
  void publishDeltas(std::deque<Version>& versions);

  Ingest& ingest_;
  Writers writers_;
  Ros2Bridge* ros2_;
  FoxgloveRoom* foxglove_;  // null: the Foxglove endpoint is off
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Version> versions_;
  std::shared_ptr<const MapView> delta_base_;  // publish thread: the last version sent a delta
};

}  // namespace densemap::server
