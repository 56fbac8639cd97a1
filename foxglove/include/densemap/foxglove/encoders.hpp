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

// The occupied cells as a foxglove.SceneUpdate stream: an entity per z-layer of a map block
// (8 x 8 cells: one 64-bit word of the block's mask) holding a cube per occupied cell
// (log-odds > 0), coloured by height (hue cycling every kHeightCycleM), as RViz colours an
// OctoMap. An entity depends only on which of its cells are occupied, so a version that only
// strengthens or frees cells resends nothing, and a changed cell resends at most 64 cubes.
// A message is a concatenation of the fields below (protobuf's repeated fields concatenate), so
// each layer's field is encoded once and shared by every client.
inline constexpr double kHeightCycleM = 4.0;

/// The occupied cells of a block (known, log-odds > 0).
[[nodiscard]] block::BlockMask occupiedCells(const VoxelBlock& block);

/// A layer of a block: the block's key and the layer's z (0 .. 7), packed.
[[nodiscard]] inline std::uint64_t layerOf(std::uint64_t block_key, int z) {
  return block_key << 3 | static_cast<std::uint64_t>(z);
}
/// The entity id of a layer ("b<block key>z<z>").
[[nodiscard]] std::string layerEntityId(std::uint64_t layer);
/// The SceneUpdate field (entities, 2) of a layer's occupied cells (`occupied`: its word of
/// occupiedCells(); bit x + 8 y); empty when none is.
[[nodiscard]] std::string layerEntityField(const VoxelGrid& grid, std::uint64_t layer,
                                           std::uint64_t occupied);
/// The SceneUpdate field (deletions, 1) removing a layer's entity.
[[nodiscard]] std::string layerDeletionField(std::uint64_t layer);
/// The marker entity ("densemap/version", no primitives, metadata map_version = `version`) that
/// ends a client's catch-up: everything sent before it shows that map version.
[[nodiscard]] std::string versionMarkerField(std::uint64_t version);
inline constexpr std::string_view kVersionMarkerId = "densemap/version";

/// The frame id a sensor id is shown under: at most 128 characters of [A-Za-z0-9_./-], any
/// other byte as '_' (a sensor id comes from the wire; protobuf strings must be UTF-8), and
/// "sensor" for an empty id.
[[nodiscard]] std::string sensorFrameId(std::string_view sensor_id);

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
