#include "densemap/foxglove/encoders.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <set>

#include "densemap/foxglove/protocol.hpp"
#include "densemap/geometry/stamp.hpp"
#include "densemap/map/sensor_model.hpp"
#include "foxglove_schemas.pb.h"

namespace densemap::foxglove {
namespace {

namespace pb = google::protobuf;

/// A field of a message: its tag (length-delimited) and `bytes`.
std::string lengthDelimited(int field, const std::string& bytes) {
  std::string out;
  pb::io::StringOutputStream stream(&out);
  pb::io::CodedOutputStream coded(&stream);
  coded.WriteTag(static_cast<std::uint32_t>(field << 3 | 2));
  coded.WriteVarint32(static_cast<std::uint32_t>(bytes.size()));
  coded.WriteRaw(bytes.data(), static_cast<int>(bytes.size()));
  coded.Trim();
  return out;
}

void setStamp(pb::Timestamp* t, std::int64_t ns) {
  const SplitStamp split = splitStamp(ns);
  t->set_seconds(split.sec);
  t->set_nanos(static_cast<std::int32_t>(split.nanosec));
}

std::string serialized(const pb::Message& m) {
  std::string out;
  (void)m.SerializeToString(&out);
  return out;
}

}  // namespace

std::string base64(std::string_view bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const std::uint32_t v = static_cast<std::uint8_t>(bytes[i]) << 16 |
                            static_cast<std::uint8_t>(bytes[i + 1]) << 8 |
                            static_cast<std::uint8_t>(bytes[i + 2]);
    for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63];
  }
  if (const std::size_t rest = bytes.size() - i; rest > 0) {
    std::uint32_t v = static_cast<std::uint8_t>(bytes[i]) << 16;
    if (rest == 2) v |= static_cast<std::uint8_t>(bytes[i + 1]) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string protobufSchema(std::string_view full_name) {
  const pb::Descriptor* d =
      pb::DescriptorPool::generated_pool()->FindMessageTypeByName(std::string(full_name));
  if (d == nullptr) return {};
  // The file and its imports, each once, imports first.
  pb::FileDescriptorSet set;
  std::set<std::string> seen;
  std::function<void(const pb::FileDescriptor*)> add = [&](const pb::FileDescriptor* f) {
    if (!seen.insert(f->name()).second) return;
    for (int i = 0; i < f->dependency_count(); ++i) add(f->dependency(i));
    f->CopyTo(set.add_file());
  };
  add(d->file());
  return base64(serialized(set));
}

std::string layerEntityId(std::uint64_t layer) {
  return "b" + std::to_string(layer >> 3) + "z" + std::to_string(layer & 7);
}

block::BlockMask occupiedCells(const VoxelBlock& block) {
  block::BlockMask m{};
  for (int w = 0; w < block::kMaskWords; ++w) {
    // 64 comparisons into one word (vectorized), then the known cells of it.
    std::uint64_t positive = 0;
    const float* values = block.log_odds.data() + 64 * w;
    for (int j = 0; j < 64; ++j) {
      positive |= static_cast<std::uint64_t>(SensorModel::isOccupied(values[j])) << j;
    }
    m[static_cast<std::size_t>(w)] = positive & block.known[static_cast<std::size_t>(w)];
  }
  return m;
}

std::string layerEntityField(const VoxelGrid& grid, std::uint64_t layer, std::uint64_t occupied) {
  static_assert(block::kEdge * block::kEdge == 64, "a layer is one word of the block's mask");
  if (occupied == 0) return {};
  ::foxglove::SceneEntity entity;
  const double r = grid.resolution();
  const std::uint64_t block_key = layer >> 3;
  const int z_index = static_cast<int>(layer & 7) << (2 * block::kShift);
  // Hue by height, a full turn every kHeightCycleM (saturated, HSV with V = 1): one per layer.
  const double z = grid.keyToCoord(block::keyOf(block_key, z_index).z);
  const double h = 6.0 * (z / kHeightCycleM - std::floor(z / kHeightCycleM));
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  const int sector = std::min(static_cast<int>(h), 5);
  const double rgb[6][3] = {{1, x, 0}, {x, 1, 0}, {0, 1, x}, {0, x, 1}, {x, 0, 1}, {1, 0, x}};
  for (std::uint64_t bits = occupied; bits != 0; bits &= bits - 1) {
    const VoxelKey k = block::keyOf(block_key, z_index | std::countr_zero(bits));
    ::foxglove::CubePrimitive* cube = entity.add_cubes();
    auto* position = cube->mutable_pose()->mutable_position();
    position->set_x(grid.keyToCoord(k.x));
    position->set_y(grid.keyToCoord(k.y));
    position->set_z(z);
    cube->mutable_pose()->mutable_orientation()->set_w(1.0);
    cube->mutable_size()->set_x(r);
    cube->mutable_size()->set_y(r);
    cube->mutable_size()->set_z(r);
    auto* color = cube->mutable_color();
    color->set_r(rgb[sector][0]);
    color->set_g(rgb[sector][1]);
    color->set_b(rgb[sector][2]);
    color->set_a(1.0);
  }
  entity.set_frame_id("map");
  entity.set_id(layerEntityId(layer));
  return lengthDelimited(::foxglove::SceneUpdate::kEntitiesFieldNumber, serialized(entity));
}

std::string layerDeletionField(std::uint64_t layer) {
  ::foxglove::SceneEntityDeletion deletion;
  deletion.set_type(::foxglove::SceneEntityDeletion::MATCHING_ID);
  deletion.set_id(layerEntityId(layer));
  // A deletion removes entities older than its timestamp: the largest one removes any.
  deletion.mutable_timestamp()->set_seconds(253402300799);  // 9999-12-31T23:59:59Z
  return lengthDelimited(::foxglove::SceneUpdate::kDeletionsFieldNumber, serialized(deletion));
}

std::string versionMarkerField(std::uint64_t version) {
  ::foxglove::SceneEntity entity;
  entity.set_frame_id("map");
  entity.set_id(std::string(kVersionMarkerId));
  auto* kv = entity.add_metadata();
  kv->set_key("map_version");
  kv->set_value(std::to_string(version));
  return lengthDelimited(::foxglove::SceneUpdate::kEntitiesFieldNumber, serialized(entity));
}

std::string sensorFrameId(std::string_view sensor_id) {
  if (sensor_id.empty()) return "sensor";
  std::string id(sensor_id.substr(0, 128));
  for (char& c : id) {
    const bool kept = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                      c == '_' || c == '.' || c == '/' || c == '-';
    if (!kept) c = '_';
  }
  return id;
}

std::string frameTransforms(std::string_view parent, std::span<const Pose> poses) {
  ::foxglove::FrameTransforms message;
  for (const Pose& p : poses) {
    ::foxglove::FrameTransform* t = message.add_transforms();
    setStamp(t->mutable_timestamp(), p.stamp_ns);
    t->set_parent_frame_id(std::string(parent));
    t->set_child_frame_id(p.child);
    t->mutable_translation()->set_x(p.t[0]);
    t->mutable_translation()->set_y(p.t[1]);
    t->mutable_translation()->set_z(p.t[2]);
    t->mutable_rotation()->set_x(p.q[0]);
    t->mutable_rotation()->set_y(p.q[1]);
    t->mutable_rotation()->set_z(p.q[2]);
    t->mutable_rotation()->set_w(p.q[3]);
  }
  return serialized(message);
}

std::string trajectories(std::string_view frame, std::span<const Trajectory> paths,
                         std::int64_t stamp_ns) {
  ::foxglove::SceneUpdate update;
  for (const Trajectory& path : paths) {
    ::foxglove::SceneEntity* e = update.add_entities();
    setStamp(e->mutable_timestamp(), stamp_ns);
    e->set_frame_id(std::string(frame));
    e->set_id("trajectory/" + path.sensor_id);
    ::foxglove::LinePrimitive* line = e->add_lines();
    line->set_type(::foxglove::LinePrimitive::LINE_STRIP);
    line->mutable_pose()->mutable_orientation()->set_w(1.0);
    line->set_thickness(3.0);
    line->set_scale_invariant(true);
    line->mutable_color()->set_g(0.8);
    line->mutable_color()->set_b(1.0);
    line->mutable_color()->set_a(1.0);
    for (const Point3f& p : path.points) {
      ::foxglove::Point3* q = line->add_points();
      q->set_x(p.x());
      q->set_y(p.y());
      q->set_z(p.z());
    }
  }
  return serialized(update);
}

std::string voxelWindow(const MapView& view, const Point3f& center, std::uint32_t cells_xy,
                        std::uint32_t cells_z, std::string_view frame, std::int64_t stamp_ns) {
  const VoxelGrid& grid = view.grid();
  const double r = grid.resolution();
  ::foxglove::VoxelGrid message;
  setStamp(message.mutable_timestamp(), stamp_ns);
  message.set_frame_id(std::string(frame));
  // The window's corner on the cell boundary below center - half the window.
  const auto corner = [&](float c, std::uint32_t cells) {
    return (std::floor(static_cast<double>(c) / r) - static_cast<double>(cells / 2)) * r;
  };
  const double x0 = corner(center.x(), cells_xy), y0 = corner(center.y(), cells_xy),
               z0 = corner(center.z(), cells_z);
  auto* pose = message.mutable_pose();
  pose->mutable_position()->set_x(x0);
  pose->mutable_position()->set_y(y0);
  pose->mutable_position()->set_z(z0);
  pose->mutable_orientation()->set_w(1.0);
  message.set_row_count(cells_xy);
  message.set_column_count(cells_xy);
  message.mutable_cell_size()->set_x(r);
  message.mutable_cell_size()->set_y(r);
  message.mutable_cell_size()->set_z(r);
  constexpr std::uint32_t kCellBytes = 8;  // r g b a, float32 probability
  message.set_cell_stride(kCellBytes);
  message.set_row_stride(kCellBytes * cells_xy);
  message.set_slice_stride(kCellBytes * cells_xy * cells_xy);
  const char* names[] = {"red", "green", "blue", "alpha"};
  for (std::uint32_t i = 0; i < 4; ++i) {
    auto* f = message.add_fields();
    f->set_name(names[i]);
    f->set_offset(i);
    f->set_type(::foxglove::PackedElementField::UINT8);
  }
  auto* f = message.add_fields();
  f->set_name("probability");
  f->set_offset(4);
  f->set_type(::foxglove::PackedElementField::FLOAT32);
  std::string data(std::size_t{kCellBytes} * cells_xy * cells_xy * cells_z, '\0');
  for (std::uint32_t z = 0; z < cells_z; ++z) {
    for (std::uint32_t y = 0; y < cells_xy; ++y) {
      for (std::uint32_t x = 0; x < cells_xy; ++x) {
        char* cell = data.data() + kCellBytes * (x + cells_xy * (y + std::size_t{cells_xy} * z));
        float p = std::numeric_limits<float>::quiet_NaN();
        const Point3f c(static_cast<float>(x0 + (x + 0.5) * r),
                        static_cast<float>(y0 + (y + 0.5) * r),
                        static_cast<float>(z0 + (z + 0.5) * r));
        if (const auto key = grid.pointToKey(c)) {
          if (const auto l = view.logOdds(*key)) {
            p = static_cast<float>(1.0 / (1.0 + std::exp(-static_cast<double>(*l))));
            if (SensorModel::isOccupied(*l)) {
              cell[0] = static_cast<char>(255);
              cell[1] = static_cast<char>(std::lround(255 * std::clamp(2.0 * (1.0 - p), 0.0, 1.0)));
              cell[3] = static_cast<char>(255);
            }
          }
        }
        std::memcpy(cell + 4, &p, 4);
      }
    }
  }
  message.set_data(std::move(data));
  return serialized(message);
}

std::string statusObject(const ServerStatus& s) {
  const auto u = [](std::uint64_t v) { return std::to_string(v); };
  const auto d = [](double v) {
    if (!std::isfinite(v)) return std::string("null");
    char text[32];
    std::snprintf(text, sizeof text, "%.6g", v);
    return std::string(text);
  };
  std::string out = "{";
  out += "\"map_version\":" + u(s.map_version) + ",\"known_cells\":" + u(s.known_cells) +
         ",\"memory_bytes\":" + u(s.memory_bytes) + ",\"received\":" + u(s.received) +
         ",\"integrated\":" + u(s.integrated) + ",\"dropped\":" + u(s.dropped) +
         ",\"rejected\":" + u(s.rejected) +
         ",\"last_reject_reason\":" + jsonString(s.last_reject_reason) +
         ",\"latency_p50_ms\":" + d(s.latency_p50_ms) +
         ",\"latency_p99_ms\":" + d(s.latency_p99_ms) + ",\"uptime_s\":" + d(s.uptime_s) +
         ",\"rss_bytes\":" + u(s.rss_bytes) + ",\"cpu_s\":" + d(s.cpu_s) +
         ",\"queries_answered\":" + u(s.queries_answered) +
         ",\"queries_rejected\":" + u(s.queries_rejected) +
         ",\"decayed_cells\":" + u(s.decayed_cells) + ",\"evicted_cells\":" + u(s.evicted_cells) +
         ",\"foxglove_clients\":" + u(s.foxglove_clients) +
         ",\"foxglove_dropped_frames\":" + u(s.foxglove_dropped_frames) +
         ",\"foxglove_closed_clients\":" + u(s.foxglove_closed_clients) +
         ",\"foxglove_rejected\":" + u(s.foxglove_rejected) +
         ",\"reintegrating\":" + (s.history.reintegrating ? "true" : "false") +
         ",\"reintegration_done\":" + u(s.history.reintegration_done) +
         ",\"reintegration_total\":" + u(s.history.reintegration_total) +
         ",\"reintegrations\":" + u(s.history.reintegrations) + ",\"sensors\":[";
  for (std::size_t i = 0; i < s.sensors.size(); ++i) {
    const SensorCounters& c = s.sensors[i];
    out += std::string(i ? "," : "") + "{\"sensor_id\":" + jsonString(c.sensor_id) +
           ",\"received\":" + u(c.received) + ",\"integrated\":" + u(c.integrated) +
           ",\"dropped\":" + u(c.dropped) + ",\"rejected\":" + u(c.rejected) +
           ",\"latency_p50_ms\":" + d(c.latency_p50_ms) +
           ",\"latency_p99_ms\":" + d(c.latency_p99_ms) + "}";
  }
  return out + "]}";
}

std::string statusJsonSchema() {
  return R"({"type":"object","title":"densemap server status","properties":{)"
         R"("map_version":{"type":"integer"},"known_cells":{"type":"integer"},)"
         R"("memory_bytes":{"type":"integer"},"received":{"type":"integer"},)"
         R"("integrated":{"type":"integer"},"dropped":{"type":"integer"},)"
         R"("rejected":{"type":"integer"},"last_reject_reason":{"type":"string"},)"
         R"("latency_p50_ms":{"type":"number"},"latency_p99_ms":{"type":"number"},)"
         R"("uptime_s":{"type":"number"},"rss_bytes":{"type":"integer"},"cpu_s":{"type":"number"},)"
         R"("queries_answered":{"type":"integer"},"queries_rejected":{"type":"integer"},)"
         R"("decayed_cells":{"type":"integer"},"evicted_cells":{"type":"integer"},)"
         R"("foxglove_clients":{"type":"integer"},"foxglove_dropped_frames":{"type":"integer"},)"
         R"("foxglove_closed_clients":{"type":"integer"},"foxglove_rejected":{"type":"integer"},)"
         R"("reintegrating":{"type":"boolean"},"reintegration_done":{"type":"integer"},)"
         R"("reintegration_total":{"type":"integer"},"reintegrations":{"type":"integer"},)"
         R"("sensors":{"type":"array","items":{"type":"object","properties":{)"
         R"("sensor_id":{"type":"string"},"received":{"type":"integer"},)"
         R"("integrated":{"type":"integer"},"dropped":{"type":"integer"},)"
         R"("rejected":{"type":"integer"},"latency_p50_ms":{"type":"number"},)"
         R"("latency_p99_ms":{"type":"number"}}}}}})";
}

}  // namespace densemap::foxglove
