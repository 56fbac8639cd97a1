#pragma once

// What densemap's Foxglove channels carry, encoded: the schemas a channel advertises, and the
// messages built from a map version, a scan and the server's status. No sockets, no threads.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "densemap/geometry/point_cloud.hpp"
#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/map/voxel_block.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/wire/server_status.hpp"

namespace densemap::foxglove {

/// A protobuf channel's schema: the base64 FileDescriptorSet of the file that defines
/// `full_name` (e.g. "foxglove.SceneUpdate") and of its imports. Empty for an unknown name.
[[nodiscard]] std::string protobufSchema(std::string_view full_name);
[[nodiscard]] std::string base64(std::string_view bytes);

// The occupied cells as a foxglove.SceneUpdate stream: an entity per map block holding a cube
// per occupied cell (log-odds > 0), coloured by probability. A message is a concatenation of
// the fields below (protobuf's repeated fields concatenate), so each block's field is encoded
// once and shared by every client.

/// The entity id of a block ("b" and its key in decimal).
[[nodiscard]] std::string blockEntityId(std::uint64_t block_key);
/// The SceneUpdate field (entities, 2) of one block's occupied cells; empty when it has none.
[[nodiscard]] std::string blockEntityField(const VoxelGrid& grid, std::uint64_t block_key,
                                           const VoxelBlock& block);
/// The SceneUpdate field (deletions, 1) removing a block's entity.
[[nodiscard]] std::string blockDeletionField(std::uint64_t block_key);
/// The marker entity ("densemap/version", no primitives, metadata map_version = `version`) that
/// ends a client's catch-up: everything sent before it shows that map version.
[[nodiscard]] std::string versionMarkerField(std::uint64_t version);
inline constexpr std::string_view kVersionMarkerId = "densemap/version";
/// The probability shown for a log-odds value (quantized to 0.05: colours do not change, and no
/// block is resent, for small changes).
[[nodiscard]] double shownProbability(float log_odds);

/// foxglove.FrameTransforms: `parent` -> `child` at `stamp_ns`.
struct Pose {
  std::string child;
  double t[3] = {0, 0, 0};
  double q[4] = {0, 0, 0, 1};  // x y z w
  std::int64_t stamp_ns = 0;
};
[[nodiscard]] std::string frameTransforms(std::string_view parent, std::span<const Pose> poses);

/// foxglove.SceneUpdate: one line-strip entity per sensor ("trajectory/<id>") through its poses.
struct Trajectory {
  std::string sensor_id;
  std::vector<Point3f> points;
};
[[nodiscard]] std::string trajectories(std::string_view frame, std::span<const Trajectory> paths,
                                       std::int64_t stamp_ns);

/// foxglove.VoxelGrid of the cells in `cells` cells a side around `center` (z-y-x order): per
/// cell red, green, blue, alpha (uint8; alpha 0 for unknown and free cells) and the occupancy
/// probability (float32, NaN for unknown).
[[nodiscard]] std::string voxelWindow(const MapView& view, const Point3f& center,
                                      std::uint32_t cells_xy, std::uint32_t cells_z,
                                      std::string_view frame, std::int64_t stamp_ns);

/// The server's status as a JSON object (the status channel; schema: statusJsonSchema()).
[[nodiscard]] std::string statusObject(const ServerStatus& status);
[[nodiscard]] std::string statusJsonSchema();

}  // namespace densemap::foxglove
