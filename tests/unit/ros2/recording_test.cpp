// ROS 2 recordings: CDR PointCloud2 / TFMessage both ways, MCAP bags written and read back in
// every chunk kind, and bags cut short or corrupted (a user's own recordings).
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/ros2/cdr.hpp"
#include "densemap/ros2/db3.hpp"
#include "densemap/ros2/mcap.hpp"
#include "densemap/ros2/recording.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap::ros2 {
namespace {

std::span<const std::uint8_t> bytesOf(const std::string& s) {
  return {reinterpret_cast<const std::uint8_t*>(s.data()), s.size()};
}

TEST(Cdr, PointCloud2AndTfMessageRoundTrip) {
  const std::vector<float> xyz{1.5F, -2.0F, 3.25F, 4.0F, 5.0F, -6.5F};
  const std::string cloud_bytes = encodeCdrPointCloud2({1'700'000'000'123'456'789, "lidar"}, xyz);
  auto cloud = decodeCdrPointCloud2(bytesOf(cloud_bytes));
  ASSERT_TRUE(cloud) << cloud.error().message;
  EXPECT_EQ(cloud->header.stamp_ns, 1'700'000'000'123'456'789);
  EXPECT_EQ(cloud->header.frame_id, "lidar");
  ASSERT_EQ(cloud->fields.size(), 3U);
  EXPECT_EQ(cloud->fields[2].name, "z");
  EXPECT_EQ(cloud->fields[2].offset, 8U);
  auto points = decodePointCloud2(cloud->view(), 100);
  ASSERT_TRUE(points);
  EXPECT_EQ(points->xyz, xyz);
  auto header = decodeCdrCloudHeader(bytesOf(cloud_bytes));
  ASSERT_TRUE(header);
  EXPECT_EQ(header->frame_id, "lidar");

  CdrTransform t{
      {42, "odom"}, "base_link", {42, {1, 2, 3}, Eigen::Quaterniond(0.5, 0.5, 0.5, 0.5)}};
  const std::vector<CdrTransform> in{t, t};
  auto out = decodeCdrTfMessage(bytesOf(encodeCdrTfMessage(in)));
  ASSERT_TRUE(out) << out.error().message;
  ASSERT_EQ(out->size(), 2U);
  EXPECT_EQ((*out)[1].header.frame_id, "odom");
  EXPECT_EQ((*out)[1].child_frame_id, "base_link");
  EXPECT_EQ((*out)[1].sample.stamp_ns, 42);
  EXPECT_EQ((*out)[1].sample.t, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ((*out)[1].sample.q.coeffs(), t.sample.q.coeffs());
}

TEST(Cdr, EveryCutAndOversizedLengthIsAnErrorNotARead) {
  const std::vector<float> xyz(30, 1.0F);
  const std::string whole = encodeCdrPointCloud2({5, "lidar"}, xyz);
  for (std::size_t n = 0; n < whole.size(); ++n) {  // ASan: no read past `n`
    const std::vector<std::uint8_t> cut(whole.begin(), whole.begin() + static_cast<long>(n));
    EXPECT_FALSE(decodeCdrPointCloud2(cut)) << "cut at " << n;
  }
  std::string huge_string = whole;
  huge_string[12] = '\xff';  // frame_id's length: 4 GiB
  huge_string[13] = '\xff';
  auto e = decodeCdrPointCloud2(bytesOf(huge_string));
  ASSERT_FALSE(e);
  EXPECT_NE(e.error().message.find("frame_id"), std::string::npos) << e.error().message;
  std::string not_cdr = whole;
  not_cdr[1] = '\x07';  // an XCDR2 or unknown encapsulation
  EXPECT_FALSE(decodeCdrPointCloud2(bytesOf(not_cdr)));
  const std::string tf = encodeCdrTfMessage(std::vector<CdrTransform>(2));
  for (std::size_t n = 0; n < tf.size(); ++n) {
    EXPECT_FALSE(decodeCdrTfMessage(bytesOf(tf.substr(0, n)))) << "cut at " << n;
  }
}

/// A small simulated dataset and its bag in `compression`.
struct Bag {
  test::TempDir dir;
  std::filesystem::path data = dir.path() / "data", bag;
  explicit Bag(McapCompression compression, int scans = 4, const std::string& name = "run.mcap")
      : bag(dir.path() / name) {
    SequenceOptions o;
    o.scene = "indoor";
    o.sensor = "vlp16";
    o.columns = 200;
    o.scans = scans;
    o.ground_truth_resolution_m = 0;
    EXPECT_TRUE(writeSimulatedSequence(o, data));
    auto source = openScanSource(data);
    EXPECT_TRUE(source);
    auto ok = writeRecording(**source, 0, (*source)->size(), bag, compression);
    EXPECT_TRUE(ok) << ok.error().message;
  }
};

TEST(Mcap, ABagReadsBackTheDatasetsScansInEveryChunkKind) {
  for (McapCompression c :
       {McapCompression::kNone, McapCompression::kZstd, McapCompression::kLz4}) {
    Bag b(c);
    auto dataset = openScanSource(b.data);
    auto bag = openAnyScanSource(b.bag);
    ASSERT_TRUE(dataset && bag) << (bag ? "" : bag.error().message);
    ASSERT_EQ((*bag)->size(), (*dataset)->size());
    EXPECT_NE((*bag)->describe().find("4 clouds on /points in frame map"), std::string::npos)
        << (*bag)->describe();
    std::int64_t last_stamp = 0;
    for (std::size_t i = 0; i < (*bag)->size(); ++i) {
      auto expected = (*dataset)->load(i);
      auto got = (*bag)->load(i);
      ASSERT_TRUE(expected && got) << (got ? "" : got.error().message);
      EXPECT_EQ(got->points, expected->points) << "scan " << i;
      EXPECT_TRUE(got->T_world_sensor.isApprox(expected->T_world_sensor, 1e-12)) << "scan " << i;
      ASSERT_TRUE(got->stamp_ns);
      EXPECT_GT(*got->stamp_ns, last_stamp);
      last_stamp = *got->stamp_ns;
    }
  }
}

TEST(Db3, ARosbag2SqliteBagReadsBackTheDatasetsScansAsADirectoryToo) {
  Bag b(McapCompression::kNone, 4, "run_0.db3");
  auto dataset = openScanSource(b.data);
  // rosbag2's layout: a directory with metadata.yaml and the storage file.
  const auto directory = b.dir.path() / "bag";
  std::filesystem::create_directories(directory);
  std::filesystem::copy_file(b.bag, directory / "run_0.db3");
  std::ofstream(directory / "metadata.yaml") << "rosbag2_bagfile_information:\n";
  for (const auto& path : {b.bag, directory}) {
    auto bag = openAnyScanSource(path);
    ASSERT_TRUE(dataset && bag) << (bag ? "" : bag.error().message);
    ASSERT_EQ((*bag)->size(), 4U);
    EXPECT_NE((*bag)->describe().find("rosbag2 SQLite bag"), std::string::npos)
        << (*bag)->describe();
    for (std::size_t i = 0; i < 4; ++i) {
      auto expected = (*dataset)->load(i);
      auto got = (*bag)->load(i);
      ASSERT_TRUE(expected && got) << (got ? "" : got.error().message);
      EXPECT_EQ(got->points, expected->points);
      EXPECT_TRUE(got->T_world_sensor.isApprox(expected->T_world_sensor, 1e-12));
    }
  }
  // Not SQLite, and SQLite without rosbag2's tables: refused with the reason.
  const auto junk = b.dir.path() / "junk.db3";
  ASSERT_TRUE(writeFileAtomically(junk, std::string(5000, 'x')));
  auto refused = openAnyScanSource(junk);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("junk.db3"), std::string::npos) << refused.error().message;
  const auto other = b.dir.path() / "other.db3";
  ASSERT_TRUE(writeDb3(other, {}, {}));
  auto no_clouds = openAnyScanSource(other);
  ASSERT_FALSE(no_clouds);
  EXPECT_NE(no_clouds.error().message.find("no sensor_msgs/msg/PointCloud2"), std::string::npos)
      << no_clouds.error().message;
}

TEST(Mcap, ABagCutShortKeepsItsCompleteChunks) {
  McapWriter w(McapCompression::kZstd, 1);  // a chunk per message
  const std::uint16_t schema = w.addSchema("std_msgs/msg/String", "ros2msg", "string data\n");
  const std::uint16_t channel = w.addChannel(schema, "/chatter", "cdr");
  for (int i = 0; i < 10; ++i)
    w.write(channel, 100 + i, std::string(50 + i, static_cast<char>('a' + i)));
  auto whole = w.finish();
  ASSERT_TRUE(whole);
  auto all = McapReader::fromBytes(*whole);
  ASSERT_TRUE(all);
  ASSERT_EQ((*all)->messages().size(), 10U);
  EXPECT_TRUE((*all)->truncated().empty());
  EXPECT_EQ((*all)->channel(channel)->topic, "/chatter");
  EXPECT_EQ((*all)->channel(channel)->schema_name, "std_msgs/msg/String");
  auto fifth = (*all)->data((*all)->messages()[5]);
  ASSERT_TRUE(fifth);
  EXPECT_EQ(*fifth, std::string(55, 'f'));
  std::size_t last = 10;
  for (std::size_t cut = whole->size() - 1; cut > 8; cut -= 7) {
    auto part = McapReader::fromBytes(whole->substr(0, cut));
    ASSERT_TRUE(part) << "cut at " << cut << ": " << part.error().message;
    const std::size_t n = (*part)->messages().size();
    // Only a cut after the data section (its end record) loses nothing and is no truncation.
    EXPECT_TRUE(!(*part)->truncated().empty() || n == 10U) << "cut at " << cut;
    EXPECT_LE(n, last);
    last = n;
    for (std::size_t k = 0; k < n; ++k) {
      auto d = (*part)->data((*part)->messages()[k]);
      ASSERT_TRUE(d);
      EXPECT_EQ(*d, std::string(50 + k, static_cast<char>('a' + k)));
    }
  }
  EXPECT_EQ(last, 0U);
  // A real bag cut in its last chunk: the scans before it, and describe() says so.
  Bag b(McapCompression::kNone, 30);  // 1.2 MB: a chunk of 1 MiB and one of the last scans
  auto bytes = readFileBytes(b.bag);
  ASSERT_TRUE(bytes);
  const auto cut = b.dir.path() / "cut.mcap";
  ASSERT_TRUE(writeFileAtomically(cut, bytes->substr(0, bytes->size() - 20'000)));
  auto partial = openRecording(cut);
  ASSERT_TRUE(partial) << partial.error().message;
  EXPECT_GT((*partial)->size(), 0U);
  EXPECT_LT((*partial)->size(), 30U);
  EXPECT_NE((*partial)->describe().find("truncated"), std::string::npos) << (*partial)->describe();
  for (std::size_t i = 0; i < (*partial)->size(); ++i) EXPECT_TRUE((*partial)->load(i));
}

TEST(Mcap, CorruptBagsAreRefusedWithTheirReason) {
  Bag b(McapCompression::kZstd);
  auto bytes = readFileBytes(b.bag);
  ASSERT_TRUE(bytes);
  const auto refused = [&](std::string changed, const std::string& reason) {
    auto r = McapReader::fromBytes(std::move(changed));
    ASSERT_FALSE(r) << reason;
    EXPECT_NE(r.error().message.find(reason), std::string::npos) << r.error().message;
  };
  std::string no_magic = *bytes;
  no_magic[1] = 'X';
  refused(no_magic, "not an MCAP file");
  // A byte flipped inside the zstd chunk's payload (the bag ends with the chunk, a data end
  // of 13 bytes, a footer of 29 and the magic): zstd or the chunk's CRC refuses it.
  std::string flipped = *bytes;
  flipped[flipped.size() - 8 - 29 - 13 - 100] ^= 0x55;
  auto r = McapReader::fromBytes(flipped);
  ASSERT_FALSE(r);
  EXPECT_TRUE(r.error().message.find("CRC") != std::string::npos ||
              r.error().message.find("zstd") != std::string::npos)
      << r.error().message;
  // A chunk claiming more than the limit uncompressed.
  McapLimits small;
  small.max_chunk_bytes = 1000;
  auto limited = McapReader::fromBytes(*bytes, small);
  ASSERT_FALSE(limited);
  EXPECT_NE(limited.error().message.find("at most 1000"), std::string::npos)
      << limited.error().message;
  // A message over the limit of one message's data.
  McapLimits one_message;
  one_message.max_message_bytes = 100;
  auto too_big = McapReader::fromBytes(*bytes, one_message);
  ASSERT_FALSE(too_big);
  EXPECT_NE(too_big.error().message.find("at most 100"), std::string::npos)
      << too_big.error().message;
  // Not a bag at all, and an empty file.
  refused("", "not an MCAP file");
  refused(std::string(100, '\0'), "not an MCAP file");
  // A bag of no clouds is refused by the recording reader with what it lacks.
  McapWriter w(McapCompression::kNone);
  (void)w.addChannel(w.addSchema("std_msgs/msg/String", "ros2msg", ""), "/chatter", "cdr");
  const auto empty_bag = b.dir.path() / "chatter.mcap";
  auto finished = w.finish();
  ASSERT_TRUE(finished && writeFileAtomically(empty_bag, *finished));
  auto none = openRecording(empty_bag);
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().message.find("no sensor_msgs/msg/PointCloud2"), std::string::npos);
}

}  // namespace
}  // namespace densemap::ros2
