#pragma once

#include <atomic>
#include <cstdint>
#include <memory>

#include "densemap/geometry/error.hpp"
#include "densemap/pipeline/engine.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/server/foxglove_options.hpp"
#include "densemap/wire/server_status.hpp"

namespace densemap::server {

/// The Foxglove WebSocket endpoint (docs/foxglove.md): a Boost.Beast server on one thread of
/// its own. Channels: the occupied cells (foxglove.SceneUpdate, an entity per 8x8 layer of a
/// map block: a client gets every layer first, then only the layers whose occupied cells a
/// version changed), the 2D grid
/// (nav_msgs/OccupancyGrid, CDR), the latest scan (sensor_msgs/PointCloud2, CDR), the sensors'
/// poses (foxglove.FrameTransforms) and trajectories (foxglove.SceneUpdate), the status (JSON)
/// and, for dense kinds, a voxel window around the robot (foxglove.VoxelGrid).
/// It never slows the map: onVersion only records the version for the endpoint's thread; each
/// client has a send queue of at most max_queue_bytes (a frame that does not fit is dropped
/// and counted; the map channel sends layers only as the queue drains, so it never drops but
/// catches up), and a client whose write has not finished for stall_close_s is closed.
class FoxgloveRoom {
 public:
  struct Counters {
    std::uint64_t clients = 0, dropped_frames = 0, closed_clients = 0, rejected = 0;
  };
  /// Binds the listening socket (an error names the address and why, e.g. in use).
  [[nodiscard]] static Expected<std::unique_ptr<FoxgloveRoom>> create(
      const FoxgloveOptions& options, std::shared_ptr<const MapView> view);
  ~FoxgloveRoom();
  FoxgloveRoom(const FoxgloveRoom&) = delete;
  FoxgloveRoom& operator=(const FoxgloveRoom&) = delete;

  void start();
  void stop();  // closes every connection; idempotent

  /// Any thread (the pipeline's worker): records the version, its written blocks and the scan
  /// for the endpoint's thread; O(written blocks), no encoding here.
  void onVersion(const IntegrationResult& result, const std::shared_ptr<const MapView>& view);
  /// The publish thread, once a second: the status channel's next message.
  void onStatus(const ServerStatus& status);
  [[nodiscard]] Counters counters() const;
  [[nodiscard]] std::uint16_t port() const;

  struct Impl;

 private:
  explicit FoxgloveRoom(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace densemap::server
