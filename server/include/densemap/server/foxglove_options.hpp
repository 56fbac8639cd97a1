#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

namespace densemap::server {

/// The Foxglove WebSocket endpoint (config `foxglove`, docs/foxglove.md).
struct FoxgloveOptions {
  std::string address = "127.0.0.1";  // the listening address
  std::uint16_t port = 8765;
  std::uint32_t max_clients = 16;
  std::size_t max_queue_bytes = std::size_t{16} << 20;  // a client's send queue
  double stall_close_s = 10.0;  // a client whose queue stays full this long is closed
  double handshake_timeout_s = 5.0;
  struct Tls {
    std::string certificate_chain, private_key;  // PEM files
  };
  std::optional<Tls> tls;      // wss; none: ws
  double grid_period_s = 1.0;  // the 2D grid, trajectories, voxel window and status
  double grid_min_z_m = -1000.0, grid_max_z_m = 1000.0;
  bool voxels = false;  // a dense map kind: the voxel window channel
  std::uint32_t voxel_window_cells = 64;
  std::uint32_t max_trajectory_poses = 10'000;
  std::string server_name = "densemap-server";
};

}  // namespace densemap::server
