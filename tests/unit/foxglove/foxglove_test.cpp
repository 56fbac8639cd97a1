// The Foxglove protocol's operations and the channels' encoders: parsed back with protobuf's
// own parsers (JSON, the advertised FileDescriptorSet) and checked against the map cell by cell.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <set>
#include <tuple>

#include "densemap/foxglove/encoders.hpp"
#include "densemap/foxglove/protocol.hpp"
#include "densemap/map/map_factory.hpp"
#include "foxglove_schemas.pb.h"
#include "foxglove_ws.pb.h"

namespace densemap::foxglove {
namespace {

namespace pb = google::protobuf;

std::string base64Decode(const std::string& in) {
  static const std::string kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::uint32_t buffer = 0;
  int bits = 0;
  for (const char c : in) {
    if (c == '=') break;
    buffer = buffer << 6 | static_cast<std::uint32_t>(kAlphabet.find(c));
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((buffer >> bits) & 0xff);
    }
  }
  return out;
}

TEST(FoxgloveOps, ParsesSubscribeAndUnsubscribe) {
  auto op = parseClientText(
      R"({"op":"subscribe","subscriptions":[{"id":3,"channelId":1},{"id":4,"channelId":6}]})");
  ASSERT_TRUE(op) << op.error().message;
  const auto& s = std::get<Subscribe>(*op);
  ASSERT_EQ(s.subscriptions.size(), 2U);
  EXPECT_EQ(s.subscriptions[1].id, 4U);
  EXPECT_EQ(s.subscriptions[1].channel_id, 6U);
  op = parseClientText(R"({"op":"unsubscribe","subscriptionIds":[3, 4],"extra":{"x":[1]}})");
  ASSERT_TRUE(op) << op.error().message;
  EXPECT_EQ(std::get<Unsubscribe>(*op).subscription_ids, (std::vector<std::uint32_t>{3, 4}));
}

TEST(FoxgloveOps, RefusesWithAReason) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {"{op: subscribe", "not a JSON operation"},
      {R"({"subscriptions":[]})", "without \"op\""},
      {R"({"op":"advertise","channels":[]})", "capability"},
      {R"({"op":"getParameters","parameterNames":[]})", "capability"},
      {R"({"op":"explode"})", "unknown operation"},
      {R"({"op":"subscribe","subscriptions":[]})", "no subscription"},
      {R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]})", "not a JSON"},
      {R"({"op":"subscribe","subscriptions":[{"id":1.5,"channelId":1}]})", "not a JSON"},
      {R"({"op":"subscribe","subscriptions":[{"id":4294967296,"channelId":1}]})", "not a JSON"},
      {R"({"op":"subscribe","subscriptions":[{"id":"x","channelId":1}]})", "not a JSON"},
      {R"([1,2,3])", "not a JSON"},
      {std::string(60000, '['), "not a JSON"},
  };
  for (const auto& [text, expected] : cases) {
    const auto op = parseClientText(text);
    ASSERT_FALSE(op) << text.substr(0, 80);
    EXPECT_NE(op.error().message.find(expected), std::string::npos)
        << text.substr(0, 80) << ": " << op.error().message;
    EXPECT_LT(op.error().message.size(), 300U);
  }
  std::string many = R"({"op":"subscribe","subscriptions":[)";
  for (std::size_t i = 0; i <= kMaxOpItems; ++i) {
    many += (i ? "," : "") + std::string(R"({"id":)") + std::to_string(i) + R"(,"channelId":1})";
  }
  const auto op = parseClientText(many + "]}");
  ASSERT_FALSE(op);
  EXPECT_NE(op.error().message.find("at most 1024"), std::string::npos) << op.error().message;
  EXPECT_FALSE(parseClientText(std::string(kMaxClientFrameBytes + 1, ' ')));
}

TEST(FoxgloveOps, ErrorsShowNoControlOrHighBytesAndStayShort) {
  // An op name with control and non-ASCII bytes: the reason quotes at most 64 printable ones
  // (it goes back to the client in a JSON text frame, which must be valid UTF-8).
  const auto op = parseClientText("{\"op\":\"\\u0001\\u00e9" + std::string(500, 'x') + "\"}");
  ASSERT_FALSE(op);
  for (const char c : op.error().message) {
    EXPECT_TRUE(static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f);
  }
  EXPECT_LT(op.error().message.size(), 120U);
  std::mt19937 rng(7);
  for (int i = 0; i < 200; ++i) {
    std::string garbage(rng() % 300, '\0');
    for (char& c : garbage) c = static_cast<char>(rng());
    const auto r = parseClientText(garbage);
    if (!r) {
      EXPECT_LT(r.error().message.size(), 300U);
    }
  }
}

TEST(FoxgloveOps, BinaryFramesAreRefusedByOpcode) {
  const std::uint8_t publish[] = {0x01, 1, 0, 0, 0};
  EXPECT_NE(binaryFrameError(publish).find("clientPublish"), std::string::npos);
  const std::uint8_t call[] = {0x02};
  EXPECT_NE(binaryFrameError(call).find("services"), std::string::npos);
  const std::uint8_t other[] = {0xee};
  EXPECT_NE(binaryFrameError(other).find("0xee"), std::string::npos);
  EXPECT_NE(binaryFrameError({}).find("empty"), std::string::npos);
}

TEST(FoxgloveOps, FindsTheSubprotocolInTheOfferedList) {
  EXPECT_TRUE(offersSubprotocol("foxglove.websocket.v1"));
  EXPECT_TRUE(offersSubprotocol("x, foxglove.websocket.v1 ,y"));
  EXPECT_TRUE(offersSubprotocol(",,\tfoxglove.websocket.v1"));
  EXPECT_FALSE(offersSubprotocol(""));
  EXPECT_FALSE(offersSubprotocol("foxglove.websocket.v2, foxglove.websocket.v1x"));
  EXPECT_FALSE(offersSubprotocol("foxglove.websocket"));
}

TEST(FoxgloveOps, MessageDataHeaderIsLittleEndian) {
  const auto h = messageDataHeader(0x04030201U, 0x0c0b0a0908070605ULL);
  const std::array<std::uint8_t, 13> expected{0x01, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
  EXPECT_EQ(h, expected);
}

TEST(FoxgloveOps, ServerOperationsAreTheProtocolsJson) {
  const std::vector<ChannelInfo> channels{
      {7, "/a \"b\"", "protobuf", "foxglove.X", "c2NoZW1h", "protobuf"}};
  pb::Struct parsed;
  ASSERT_TRUE(pb::util::JsonStringToMessage(advertiseJson(channels), &parsed).ok());
  EXPECT_EQ(parsed.fields().at("op").string_value(), "advertise");
  const auto& ch = parsed.fields().at("channels").list_value().values(0).struct_value().fields();
  EXPECT_EQ(ch.at("id").number_value(), 7);
  EXPECT_EQ(ch.at("topic").string_value(), "/a \"b\"");
  EXPECT_EQ(ch.at("schemaName").string_value(), "foxglove.X");
  EXPECT_EQ(ch.at("schemaEncoding").string_value(), "protobuf");
  ASSERT_TRUE(pb::util::JsonStringToMessage(statusJson(StatusLevel::kInfo, "x\ny"), &parsed).ok());
  EXPECT_EQ(parsed.fields().at("level").number_value(), 0);  // printed although the default
  EXPECT_EQ(parsed.fields().at("message").string_value(), "x\ny");
  const std::vector<std::pair<std::string, std::string>> metadata{{"k", "v"}};
  ASSERT_TRUE(pb::util::JsonStringToMessage(serverInfoJson("s", "1", metadata), &parsed).ok());
  EXPECT_EQ(parsed.fields().at("op").string_value(), "serverInfo");
  EXPECT_EQ(parsed.fields().at("capabilities").list_value().values_size(), 0);
  EXPECT_EQ(parsed.fields().at("sessionId").string_value(), "1");
}

TEST(FoxgloveEncoders, Base64) {
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64(std::string("\xff\x00\x80", 3)), "/wCA");
}

TEST(FoxgloveEncoders, ProtobufSchemaHoldsTheTypeAndItsImports) {
  for (const char* name :
       {"foxglove.SceneUpdate", "foxglove.FrameTransforms", "foxglove.VoxelGrid"}) {
    pb::FileDescriptorSet set;
    ASSERT_TRUE(set.ParseFromString(base64Decode(protobufSchema(name)))) << name;
    // Built into a pool of its own, in order: each file's imports come before it.
    pb::DescriptorPool pool;
    for (const auto& file : set.file()) ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
    EXPECT_NE(pool.FindMessageTypeByName(name), nullptr) << name;
    EXPECT_NE(pool.FindFileByName("google/protobuf/timestamp.proto"), nullptr);
  }
  EXPECT_EQ(protobufSchema("foxglove.NoSuchType"), "");
}

TEST(FoxgloveEncoders, LayerEntitiesHoldEveryOccupiedCellAndConcatenate) {
  const VoxelGrid grid(0.2);
  const std::uint64_t key = block::blockOf(VoxelKey{32768 + 40, 32768 - 16, 32768 + 3});
  VoxelBlock b;
  std::set<std::tuple<double, double, double>> occupied;
  std::mt19937 rng(3);
  for (int i = 0; i < block::kVoxels; ++i) {
    if (rng() % 3 == 0) continue;  // unknown
    b.markKnown(i);
    b.log_odds[i] = static_cast<float>(static_cast<int>(rng() % 400) - 200) / 100.0F;
    if (b.log_odds[i] > 0) {
      const VoxelKey k = block::keyOf(key, i);
      occupied.emplace(grid.keyToCoord(k.x), grid.keyToCoord(k.y), grid.keyToCoord(k.z));
    }
  }
  ASSERT_GT(occupied.size(), 50U);
  // Every layer's entity, one message: the block's occupied cells, each once.
  const block::BlockMask mask = occupiedCells(b);
  std::string message;
  for (int z = 0; z < 8; ++z) {
    message += layerEntityField(grid, layerOf(key, z), mask[static_cast<std::size_t>(z)]);
  }
  message += layerDeletionField(layerOf(key + 1, 2)) + versionMarkerField(42);
  ::foxglove::SceneUpdate update;
  ASSERT_TRUE(update.ParseFromString(message));
  ASSERT_EQ(update.deletions_size(), 1);
  EXPECT_EQ(update.deletions(0).id(), "b" + std::to_string(key + 1) + "z2");
  std::set<std::tuple<double, double, double>> shown;
  std::set<std::string> ids;
  for (const auto& e : update.entities()) {
    ids.insert(e.id());
    if (e.id() == kVersionMarkerId) {
      EXPECT_EQ(e.metadata(0).value(), "42");
      EXPECT_EQ(e.cubes_size(), 0);
      continue;
    }
    EXPECT_EQ(e.frame_id(), "map");
    for (const auto& cube : e.cubes()) {
      const auto& p = cube.pose().position();
      EXPECT_TRUE(shown.emplace(p.x(), p.y(), p.z()).second);
      EXPECT_DOUBLE_EQ(cube.size().x(), 0.2);
      EXPECT_EQ(cube.pose().orientation().w(), 1.0);
      EXPECT_GE(cube.color().a(), 1.0);
      EXPECT_GE(std::max({cube.color().r(), cube.color().g(), cube.color().b()}), 1.0);
    }
  }
  EXPECT_EQ(shown, occupied);
  EXPECT_EQ(ids.size(), static_cast<std::size_t>(update.entities_size()));  // ids are unique
  // A layer without an occupied cell has no entity.
  VoxelBlock free_block;
  free_block.markKnown(5);
  free_block.log_odds[5] = -1.0F;
  EXPECT_FALSE(block::anyBit(occupiedCells(free_block)));
  EXPECT_EQ(layerEntityField(grid, layerOf(key, 0), 0), "");
  // An entity depends only on which cells are occupied: a stronger hit changes nothing.
  VoxelBlock stronger = b;
  for (float& l : stronger.log_odds) l = l > 0 ? l + 0.5F : l;
  EXPECT_EQ(occupiedCells(stronger), mask);
}

TEST(FoxgloveEncoders, VoxelWindowIsTheMapAroundTheRobot) {
  auto map = makeMap(Backend::kGrid, 0.1);
  ASSERT_TRUE(map);
  const VoxelGrid grid(0.1);
  const VoxelKey occupied = *grid.pointToKey(Point3f(0.35F, -0.25F, 0.05F));
  const VoxelKey free = *grid.pointToKey(Point3f(-0.15F, 0.15F, -0.05F));
  (*map)->setLogOdds(occupied, 1.5F);
  (*map)->setLogOdds(free, -1.0F);
  const auto view = MapView::fromMap(**map, 1);
  ::foxglove::VoxelGrid message;
  ASSERT_TRUE(message.ParseFromString(voxelWindow(*view, Point3f(0, 0, 0), 16, 8, "map", 5)));
  ASSERT_EQ(message.row_count(), 16U);
  ASSERT_EQ(message.data().size(), std::size_t{8} * 16 * 16 * 8);
  int shown = 0, known = 0;
  for (std::uint32_t z = 0; z < 8; ++z) {
    for (std::uint32_t y = 0; y < 16; ++y) {
      for (std::uint32_t x = 0; x < 16; ++x) {
        const char* cell = message.data().data() + message.slice_stride() * z +
                           message.row_stride() * y + message.cell_stride() * x;
        float p = 0;
        std::memcpy(&p, cell + 4, 4);
        const Point3f c(static_cast<float>(message.pose().position().x() + (x + 0.5) * 0.1),
                        static_cast<float>(message.pose().position().y() + (y + 0.5) * 0.1),
                        static_cast<float>(message.pose().position().z() + (z + 0.5) * 0.1));
        const VoxelKey k = *grid.pointToKey(c);
        if (static_cast<unsigned char>(cell[3]) == 255) {
          ++shown;
          EXPECT_EQ(k, occupied);
        }
        if (!std::isnan(p)) {
          ++known;
          EXPECT_TRUE(k == occupied || k == free);
          EXPECT_NEAR(p, k == occupied ? 1 / (1 + std::exp(-1.5)) : 1 / (1 + std::exp(1.0)), 1e-6);
        }
      }
    }
  }
  EXPECT_EQ(shown, 1);
  EXPECT_EQ(known, 2);
}

TEST(FoxgloveEncoders, SensorFramesAreShortAndPlain) {
  EXPECT_EQ(sensorFrameId("lidar/front_1.a-b"), "lidar/front_1.a-b");
  EXPECT_EQ(sensorFrameId(""), "sensor");
  EXPECT_EQ(sensorFrameId(std::string("a\xff\"\n b", 6)), "a____b");
  EXPECT_EQ(sensorFrameId(std::string(1 << 20, 'x')).size(), 128U);
  // Through FrameTransforms: the id survives protobuf's round trip unchanged.
  const std::vector<Pose> poses{{.child = sensorFrameId("\xc3\x28 id"), .stamp_ns = -1}};
  ::foxglove::FrameTransforms decoded;
  ASSERT_TRUE(decoded.ParseFromString(frameTransforms("map", poses)));
  EXPECT_EQ(decoded.transforms(0).child_frame_id(), "___id");
  EXPECT_EQ(decoded.transforms(0).timestamp().seconds(), -1);
  EXPECT_EQ(decoded.transforms(0).timestamp().nanos(), 999'999'999);
  EXPECT_EQ(decoded.transforms(0).rotation().w(), 1.0);
}

TEST(FoxgloveEncoders, StatusIsValidJsonWhateverTheSensorIds) {
  ServerStatus s;
  s.map_version = 12;
  s.latency_p50_ms = std::nan("");
  s.sensors.push_back({.sensor_id = std::string("a\"b\\c\n\x01", 7), .received = 3});
  pb::Struct parsed;
  ASSERT_TRUE(pb::util::JsonStringToMessage(statusObject(s), &parsed).ok()) << statusObject(s);
  EXPECT_EQ(parsed.fields().at("map_version").number_value(), 12);
  EXPECT_EQ(parsed.fields()
                .at("sensors")
                .list_value()
                .values(0)
                .struct_value()
                .fields()
                .at("sensor_id")
                .string_value(),
            std::string("a\"b\\c\n\x01", 7));
  ASSERT_TRUE(pb::util::JsonStringToMessage(statusJsonSchema(), &parsed).ok());
  // Every field the status carries is in its schema.
  ASSERT_TRUE(pb::util::JsonStringToMessage(statusObject(s), &parsed).ok());
  pb::Struct schema;
  ASSERT_TRUE(pb::util::JsonStringToMessage(statusJsonSchema(), &schema).ok());
  for (const auto& [name, value] : parsed.fields()) {
    EXPECT_TRUE(schema.fields().at("properties").struct_value().fields().contains(name)) << name;
  }
}

}  // namespace
}  // namespace densemap::foxglove
