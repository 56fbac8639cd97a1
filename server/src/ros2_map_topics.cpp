#include <cstring>
#include <initializer_list>
#include <vector>

#include "densemap/planner/distance_slice.hpp"
#include "densemap/wire/topics.hpp"
#include "nav_msgs.h"
#include "octomap_msgs.h"
#include "ros2_bridge_state.hpp"
#include "sensor_msgs.h"

// The bridge's map topics (docs/ros2.md, Out): /octomap_binary, /projected_map and the
// occupied-cell centres, kept current from the versions' written blocks while someone listens.
namespace densemap::server {
namespace {

builtin_interfaces_msg_dds__Time_ rosNow() {
  const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                      std::chrono::system_clock::now().time_since_epoch())
                      .count();
  return {static_cast<std::int32_t>(ns / 1'000'000'000),
          static_cast<std::uint32_t>(ns % 1'000'000'000)};
}

/// /octomap_binary: the (pruned) OcTree's binary stream.
void writeOctomap(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
                  double resolution, ros2::MapTopicsState& map) {
  std::string bytes = map.binaryData();
  octomap_msgs_msg_dds__Octomap_ msg{};
  msg.header = header;
  msg.binary = true;
  msg.id = const_cast<char*>("OcTree");
  msg.resolution = resolution;
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(bytes.size());
  msg.data._buffer = reinterpret_cast<std::int8_t*>(bytes.data());
  msg.data._release = false;
  (void)dds::write(writer, &msg);
}

/// A nav_msgs/OccupancyGrid of `grid` (ros2::GridImage or Costmap: origin, resolution, width,
/// height, int8 cells) in the plane z = `z_m`.
template <class Grid>
void writeOccupancyGrid(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
                        Grid& grid, double z_m) {
  nav_msgs_msg_dds__OccupancyGrid_ msg{};
  msg.header = header;
  msg.info.map_load_time = header.stamp;
  msg.info.resolution = static_cast<float>(grid.resolution);
  msg.info.width = grid.width;
  msg.info.height = grid.height;
  msg.info.origin.position = {grid.origin_x, grid.origin_y, z_m};
  msg.info.origin.orientation = {0.0, 0.0, 0.0, 1.0};
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(grid.data.size());
  msg.data._buffer = grid.data.data();
  msg.data._release = false;
  (void)dds::write(writer, &msg);
}

/// /projected_map: the 2D occupancy grid.
void writeGrid(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
               ros2::MapTopicsState& map) {
  ros2::GridImage grid = map.projectedGrid();
  writeOccupancyGrid(writer, header, grid, 0.0);
}

/// A PointCloud2 of `width` points of `names` (float32 each, packed in that order) in `data`.
void writeFloatCloud(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
                     std::initializer_list<const char*> names, std::uint32_t width,
                     std::vector<std::uint8_t>& data) {
  std::vector<sensor_msgs_msg_dds__PointField_> fields;
  std::uint32_t offset = 0;
  for (const char* name : names) {
    fields.push_back({const_cast<char*>(name), offset, 7, 1});  // 7: FLOAT32
    offset += 4;
  }
  sensor_msgs_msg_dds__PointCloud2_ msg{};
  msg.header = header;
  msg.height = 1;
  msg.width = width;
  msg.fields._length = msg.fields._maximum = static_cast<std::uint32_t>(fields.size());
  msg.fields._buffer = fields.data();
  msg.fields._release = false;
  msg.is_bigendian = false;
  msg.point_step = offset;
  msg.row_step = static_cast<std::uint32_t>(data.size());
  msg.data._length = msg.data._maximum = static_cast<std::uint32_t>(data.size());
  msg.data._buffer = data.data();
  msg.data._release = false;
  msg.is_dense = true;
  (void)dds::write(writer, &msg);
}

/// The occupied cells' centres as a PointCloud2 (x, y, z float32).
void writeCenters(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
                  ros2::MapTopicsState& map) {
  const std::vector<Point3f> centers = map.occupiedCenters();
  std::vector<std::uint8_t> data(centers.size() * 12);
  for (std::size_t i = 0; i < centers.size(); ++i) {
    std::memcpy(data.data() + 12 * i, centers[i].data(), 12);
  }
  writeFloatCloud(writer, header, {"x", "y", "z"}, static_cast<std::uint32_t>(centers.size()),
                  data);
}

/// The distance field's layer: PointCloud2 with x, y, z and distance (float32 each).
void writeSlice(const dds::Entity& writer, const std_msgs_msg_dds__Header_& header,
                const std::vector<std::array<float, 4>>& points) {
  std::vector<std::uint8_t> data(points.size() * 16);
  if (!points.empty()) std::memcpy(data.data(), points.data(), data.size());
  writeFloatCloud(writer, header, {"x", "y", "z", "distance"},
                  static_cast<std::uint32_t>(points.size()), data);
}

}  // namespace

void Ros2Bridge::publishMaps() {
  std::vector<std::uint64_t> blocks;
  std::shared_ptr<const MapView> latest;
  {
    std::lock_guard lock(versions_mutex_);
    blocks.swap(pending_blocks_);
    latest = latest_;
  }
  Topics& s = *state_;
  if (latest == nullptr) return;
  // Like map/delta: while no ROS tool listens, no state is kept (an OcTree update per changed
  // cell is the costly part); the first reader gets the map built once from the latest version.
  const auto listened = [](const dds::Entity& w) {
    dds_publication_matched_status_t m{};
    return w.get() > 0 && dds_get_publication_matched_status(w.get(), &m) >= 0 &&
           m.current_count > 0;
  };
  // The distance field's topics, from the field and the version it was updated to.
  if (listened(dds_->slice_writer) || listened(dds_->costmap_writer)) {
    ingest_.withDistanceField([&](const DistanceField& field, const MapView& view) {
      if (view.knownCells() == 0 || s.field_written == view.version()) return;
      s.field_written = view.version();
      const std::string frame = options_.world_frame;
      std_msgs_msg_dds__Header_ header{rosNow(), const_cast<char*>(frame.c_str())};
      if (dds_->slice_writer.get() > 0) {
        writeSlice(dds_->slice_writer, header, distanceSlice(field, options_.esdf_slice_z_m));
      }
      if (dds_->costmap_writer.get() > 0) {
        Costmap costmap =
            inflatedCostmap(field, view, options_.esdf_slice_z_m, options_.robot_radius_m);
        if (costmap.width > 0) {
          writeOccupancyGrid(dds_->costmap_writer, header, costmap, options_.esdf_slice_z_m);
        }
      }
    });
  }
  if (!listened(dds_->octomap_writer) && !listened(dds_->grid_writer) &&
      !listened(dds_->centers_writer)) {
    if (s.published != nullptr) s.map->clear();
    s.published = nullptr;
    return;
  }
  if (s.published != nullptr && latest->version() == s.published->version()) return;
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  s.map->update(s.published.get(), *latest, blocks);
  s.published = latest;
  // As octomap_server: an empty map is not published (no 0-byte Octomap, no 0x0 grid), and a
  // version already written is not written again.
  if (latest->knownCells() == 0 || s.written == latest->version()) return;
  s.written = latest->version();

  const std::string frame = options_.world_frame;
  std_msgs_msg_dds__Header_ header{rosNow(), const_cast<char*>(frame.c_str())};
  const double resolution = latest->grid().resolution();
  if (dds_->octomap_writer.get() > 0)
    writeOctomap(dds_->octomap_writer, header, resolution, *s.map);
  if (dds_->grid_writer.get() > 0) writeGrid(dds_->grid_writer, header, *s.map);
  if (dds_->centers_writer.get() > 0) writeCenters(dds_->centers_writer, header, *s.map);
  std::lock_guard lock(counters_mutex_);
  ++counters_.maps_published;
}

}  // namespace densemap::server
