// The scan store (core/store): records round-trip bit for bit; a damaged, truncated or
// oversized record is an error, never a scan; the store keeps its byte bound, replaces poses,
// finds scans by sensor and stamp, and removes the files of the scans it drops.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <random>

#include "densemap/store/scan_store.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap {
namespace {

RawScan randomScan(std::uint64_t seq, std::size_t points, bool intensities, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-40.0F, 40.0F);
  RawScan s;
  s.sensor_id = "lidar/" + std::to_string(seed % 3);
  s.seq = seq;
  s.stamp_ns = static_cast<std::int64_t>(seq) * 100'000'000 - 7;
  s.t_world_sensor = {1.5 * static_cast<double>(seq), -2.25, 0.125};
  s.q_world_sensor = {0.5, 0.5, -0.5, 0.5};
  for (std::size_t i = 0; i < 3 * points; ++i) s.xyz.push_back(coord(rng));
  if (intensities) {
    for (std::size_t i = 0; i < points; ++i) s.intensity.push_back(coord(rng));
  }
  return s;
}

void expectSameScan(const RawScan& a, const RawScan& b) {
  EXPECT_EQ(a.sensor_id, b.sensor_id);
  EXPECT_EQ(a.seq, b.seq);
  EXPECT_EQ(a.stamp_ns, b.stamp_ns);
  EXPECT_EQ(a.t_world_sensor, b.t_world_sensor);
  EXPECT_EQ(a.q_world_sensor, b.q_world_sensor);
  ASSERT_EQ(a.xyz.size(), b.xyz.size());
  EXPECT_EQ(std::memcmp(a.xyz.data(), b.xyz.data(), a.xyz.size() * sizeof(float)), 0);
  EXPECT_EQ(a.intensity, b.intensity);
}

TEST(ScanStore, ARecordDecodesToTheScanItEncodes) {
  for (const bool intensities : {false, true}) {
    const RawScan scan = randomScan(3, 5000, intensities, 11);
    const auto record = encodeScanRecord(scan);
    ASSERT_FALSE(record.empty());
    auto back = decodeScanRecord(record);
    ASSERT_TRUE(back) << back.error().message;
    expectSameScan(scan, *back);
  }
  auto empty = decodeScanRecord(encodeScanRecord(RawScan{}));
  ASSERT_TRUE(empty) << empty.error().message;
  EXPECT_TRUE(empty->xyz.empty());
}

TEST(ScanStore, ADamagedTruncatedOrOversizedRecordIsAnError) {
  const auto record = encodeScanRecord(randomScan(1, 300, true, 2));
  for (std::size_t at :
       {std::size_t{0}, std::size_t{5}, std::size_t{12}, record.size() / 2, record.size() - 1}) {
    auto bad = record;
    bad[at] ^= 0x40;
    EXPECT_FALSE(decodeScanRecord(bad)) << "byte " << at << " flipped";
  }
  for (std::size_t n : {std::size_t{0}, std::size_t{15}, std::size_t{16}, record.size() - 1}) {
    EXPECT_FALSE(decodeScanRecord(std::span(record).first(n))) << n << " bytes";
  }
  auto huge = record;
  const std::uint32_t raw_size = 0xFFFFFFF0U;  // would allocate 4 GiB
  std::memcpy(huge.data() + 8, &raw_size, 4);
  auto refused = decodeScanRecord(huge);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("more than a scan may hold"), std::string::npos)
      << refused.error().message;
}

TEST(ScanStore, KeepsItsBoundReplacesPosesFindsByStampAndRemovesDroppedFiles) {
  test::TempDir dir;
  const std::size_t one = encodeScanRecord(randomScan(1, 2000, false, 1)).size();
  auto store = ScanStore::create(
      {.directory = dir.path(), .max_bytes = 20 * one + one / 2, .segment_bytes = 4 * one});
  ASSERT_TRUE(store) << store.error().message;
  ScanStore& s = **store;
  std::vector<RawScan> scans;
  for (std::uint64_t i = 0; i < 20; ++i) {
    scans.push_back(randomScan(i, 2000, false, 1));
    scans.back().sensor_id = "a";
    auto index = s.append(scans.back());
    ASSERT_TRUE(index) << index.error().message;
    EXPECT_EQ(*index, i);
  }
  auto full = s.append(randomScan(20, 2000, false, 1));
  ASSERT_FALSE(full) << "past max_bytes";
  EXPECT_EQ(s.end(), 20U);
  for (std::uint64_t i : {0U, 7U, 19U}) {
    auto back = s.read(i);
    ASSERT_TRUE(back) << back.error().message;
    expectSameScan(scans[i], *back);
  }
  ASSERT_EQ(s.find("a", scans[7].stamp_ns), 7U);
  EXPECT_FALSE(s.find("a", scans[7].stamp_ns + 1));
  EXPECT_FALSE(s.find("b", scans[7].stamp_ns));
  ASSERT_TRUE(s.setPose(7, {9, 8, 7}, {0, 1, 0, 0}));
  auto moved = s.read(7);
  ASSERT_TRUE(moved);
  EXPECT_EQ(moved->t_world_sensor, (std::array<double, 3>{9, 8, 7}));
  EXPECT_EQ(moved->q_world_sensor, (std::array<double, 4>{0, 1, 0, 0}));
  EXPECT_EQ(moved->xyz, scans[7].xyz);

  const auto files = [&] {
    std::size_t n = 0;
    for (const auto& e : std::filesystem::directory_iterator(s.directory())) n += e.exists();
    return n;
  };
  EXPECT_EQ(files(), 5U);  // 4 scans a segment
  s.dropBefore(9);         // segments 0-3 and 4-7 hold only dropped scans
  EXPECT_EQ(s.first(), 9U);
  EXPECT_EQ(files(), 3U);
  EXPECT_FALSE(s.read(8));
  EXPECT_FALSE(s.find("a", scans[7].stamp_ns));
  EXPECT_FALSE(s.setPose(7, {0, 0, 0}, {1, 0, 0, 0}));
  auto appended = s.append(scans[0]);  // room again
  ASSERT_TRUE(appended) << appended.error().message;
  EXPECT_EQ(*appended, 20U);
  s.clear();
  EXPECT_EQ(s.first(), 21U);
  EXPECT_EQ(s.bytes(), 0U);
  EXPECT_EQ(files(), 0U);
  const auto where = s.directory();
  store->reset();
  EXPECT_FALSE(std::filesystem::exists(where)) << "the store removes its directory";
}

TEST(ScanStore, ADirectoryThatCannotBeMadeIsAnError) {
  test::TempDir dir;
  const auto file = dir.path() / "plain-file";
  { std::ofstream(file) << "x"; }
  auto store = ScanStore::create({.directory = file / "below"});
  ASSERT_FALSE(store);
  EXPECT_NE(store.error().message.find("scan store"), std::string::npos);
}

}  // namespace
}  // namespace densemap
