#include <bzlib.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <fstream>

#include "densemap/io/dataset_writer.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/io/text_lines.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap {
namespace {

void writeText(const std::filesystem::path& p, const std::string& s) {
  std::ofstream(p, std::ios::binary) << s;
}

Scan makeScan(std::size_t id, int n) {
  Scan s;
  s.id = id;
  s.T_world_sensor = transformFromTranslationQuaternion({1.0 * id, -2.0, 0.5}, 0.9, 0.1, 0.2, 0.3);
  for (int i = 0; i < n; ++i) {
    s.points.emplace_back(0.1F * i, -0.25F * i, 1.0F + 0.01F * i);
    s.intensities.push_back(static_cast<float>(i));
  }
  return s;
}

TEST(DatasetDirectory, WriteThenReadIsIdentity) {
  test::TempDir dir;
  auto writer = DatasetWriter::create(dir.path());
  ASSERT_TRUE(writer) << writer.error().message;
  for (std::size_t id : {0U, 1U, 3U}) ASSERT_TRUE(writer->write(makeScan(id, 50)));
  ASSERT_TRUE(writer->finish());

  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source) << source.error().message;
  ASSERT_EQ((*source)->size(), 3U);
  auto third = (*source)->load(2);
  ASSERT_TRUE(third) << third.error().message;
  const Scan expected = makeScan(3, 50);
  EXPECT_EQ(third->id, 3U);
  EXPECT_EQ(third->points, expected.points);
  EXPECT_EQ(third->intensities, expected.intensities);
  EXPECT_TRUE(third->T_world_sensor.isApprox(expected.T_world_sensor, 1e-12));
  EXPECT_EQ(third->pointsWorld(), transformPoints(expected.T_world_sensor, expected.points));
}

TEST(DatasetDirectory, TruncatedScanFileIsAClearError) {
  test::TempDir dir;
  auto writer = DatasetWriter::create(dir.path());
  ASSERT_TRUE(writer->write(makeScan(0, 10)));
  ASSERT_TRUE(writer->finish());
  std::filesystem::resize_file(dir.path() / "scans" / "000000.bin", 16 * 10 - 3);
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source);
  auto scan = (*source)->load(0);
  ASSERT_FALSE(scan);
  EXPECT_NE(scan.error().message.find("not a multiple of 16"), std::string::npos);
  EXPECT_NE(scan.error().message.find("000000.bin"), std::string::npos);
}

TEST(DatasetDirectory, MissingOrBrokenPosesAreClearErrors) {
  test::TempDir dir;
  auto writer = DatasetWriter::create(dir.path());
  ASSERT_TRUE(writer->write(makeScan(5, 3)));
  ASSERT_TRUE(writer->finish());
  writeText(dir.path() / "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");  // only scan 0's line
  auto short_poses = openScanSource(dir.path());
  ASSERT_FALSE(short_poses);
  EXPECT_NE(short_poses.error().message.find("scan 5 needs line 6"), std::string::npos);

  writeText(dir.path() / "poses.txt", "1 0 0 0 0 1 0 0 0 0 1\n");
  auto short_line = openScanSource(dir.path());
  ASSERT_FALSE(short_line);
  EXPECT_NE(short_line.error().message.find("line 1"), std::string::npos);

  writeText(dir.path() / "poses.txt", "1 0 0 nan 0 1 0 0 0 0 1 0\n");
  EXPECT_FALSE(openScanSource(dir.path()));

  // A scaled, zero or reflected rotation is a file:line error
  // (before, every scan was then refused by the server: "pose quaternion norm 27.39").
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  std::string lines;
  for (int i = 0; i < 5; ++i) lines += good;
  for (const auto& [pose, reason] : std::vector<std::pair<std::string, std::string>>{
           {"3 0 0 0 0 3 0 0 0 0 3 0\n", "orthonormal"},
           {"0 0 0 0 0 0 0 0 0 0 0 0\n", "orthonormal"},
           {"-1 0 0 0 0 1 0 0 0 0 1 0\n", "reflection"},
           {"1 0 0 1e30 0 1 0 0 0 0 1 0\n", "translation"}}) {
    writeText(dir.path() / "poses.txt", lines + pose);
    auto bad = openScanSource(dir.path());
    ASSERT_FALSE(bad) << pose;
    EXPECT_NE(bad.error().message.find("line 6"), std::string::npos) << bad.error().message;
    EXPECT_NE(bad.error().message.find(reason), std::string::npos) << bad.error().message;
  }

  std::filesystem::remove(dir.path() / "poses.txt");
  auto none = openScanSource(dir.path());
  ASSERT_FALSE(none);
  EXPECT_NE(none.error().message.find("poses"), std::string::npos);
}

TEST(ScanSource, UnknownPathsAndFormatsAreErrors) {
  test::TempDir dir;
  EXPECT_FALSE(openScanSource(dir.path() / "nope"));
  EXPECT_FALSE(openScanSource(dir.path()));  // empty directory
  writeText(dir.path() / "x.xyz", "1 2 3\n");
  EXPECT_FALSE(openScanSource(dir.path() / "x.xyz"));
}

std::string pcdHeader(const std::string& data, int points) {
  return "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
         "COUNT 1 1 1 1\nWIDTH " +
         std::to_string(points) +
         "\nHEIGHT 1\n"
         "VIEWPOINT 1 2 3 1 0 0 0\nPOINTS " +
         std::to_string(points) + "\nDATA " + data + "\n";
}

TEST(Pcd, BinaryAndAsciiReadTheSamePointsAndViewpoint) {
  test::TempDir dir;
  std::string bin = pcdHeader("binary", 2);
  const float raw[8] = {1, 2, 3, 9, -4, 5.5F, 6, 8};
  bin.append(reinterpret_cast<const char*>(raw), sizeof(raw));
  writeText(dir.path() / "a_1.pcd", bin);
  writeText(dir.path() / "a_2.pcd", pcdHeader("ascii", 2) + "1 2 3 9\n-4 5.5 6 8\n");
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source) << source.error().message;
  ASSERT_EQ((*source)->size(), 2U);
  auto a = (*source)->load(0), b = (*source)->load(1);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(a->points, b->points);
  EXPECT_EQ(a->points[1], Point3f(-4, 5.5F, 6));
  EXPECT_EQ(a->frame, PointFrame::kWorld);
  EXPECT_EQ(a->originWorld(), Point3f(1, 2, 3));
  EXPECT_EQ(a->pointsWorld(), a->points);  // world-frame points are not transformed again
}

// "nan" in an ASCII PCD is a missing return (a point the
// mapping tools drop), not a truncated file; a NaN VIEWPOINT is an error, not an empty map.
TEST(Pcd, NanPointsAreReadAndANanViewpointIsAnError) {
  test::TempDir dir;
  writeText(dir.path() / "a_1.pcd", pcdHeader("ascii", 2) + "nan nan nan 0\n-4 5.5 6 8\n");
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source) << source.error().message;
  auto scan = (*source)->load(0);
  ASSERT_TRUE(scan) << scan.error().message;
  ASSERT_EQ(scan->points.size(), 2U);
  EXPECT_FALSE(scan->points[0].allFinite());
  EXPECT_EQ(scan->removeNonFinitePoints(), 1U);
  EXPECT_EQ(scan->points[0], Point3f(-4, 5.5F, 6));
  EXPECT_EQ(scan->intensities, std::vector<float>{8});

  test::TempDir other;
  std::string header = pcdHeader("ascii", 1);
  header.replace(header.find("VIEWPOINT 1 2 3"), 15, "VIEWPOINT nan 2 3");
  writeText(other.path() / "b_1.pcd", header + "1 2 3 4\n");
  auto bad = openScanSource(other.path());
  std::string message = bad ? "" : bad.error().message;
  if (bad) {
    auto loaded = (*bad)->load(0);
    ASSERT_FALSE(loaded);
    message = loaded.error().message;
  }
  EXPECT_NE(message.find("VIEWPOINT"), std::string::npos) << message;
}

TEST(Pcd, TruncatedAndMalformedFilesAreClearErrors) {
  test::TempDir dir;
  std::string bin = pcdHeader("binary", 3);
  bin.append(std::string(20, '\0'));
  writeText(dir.path() / "t.pcd", bin);
  auto t = readPcd(dir.path() / "t.pcd");
  ASSERT_FALSE(t);
  EXPECT_NE(t.error().message.find("truncated"), std::string::npos);
  writeText(dir.path() / "c.pcd", pcdHeader("binary_compressed", 1));
  EXPECT_FALSE(readPcd(dir.path() / "c.pcd"));
  writeText(dir.path() / "n.pcd", "VERSION 0.7\nFIELDS x y z\n");
  EXPECT_FALSE(readPcd(dir.path() / "n.pcd"));
  writeText(dir.path() / "a.pcd", pcdHeader("ascii", 2) + "1 2 3 9\n-4 5.5\n");
  EXPECT_FALSE(readPcd(dir.path() / "a.pcd"));
  // Point counts no file could hold (found by fuzz_pcd: reserving them threw): clear errors.
  for (const std::string& count : {std::string("11111110000001110001"), std::string("-1")}) {
    std::string text = pcdHeader("ascii", 1);
    text.replace(text.find("POINTS 1"), 8, "POINTS " + count);
    writeText(dir.path() / "h.pcd", text + "1 2 3 4\n");
    auto huge = readPcd(dir.path() / "h.pcd");
    ASSERT_FALSE(huge) << count;
    EXPECT_NE(huge.error().message.find("h.pcd"), std::string::npos);
  }
}

std::string bzip2(const std::string& in) {
  std::string out(in.size() + in.size() / 100 + 600, '\0');
  unsigned int size = static_cast<unsigned>(out.size());
  EXPECT_EQ(BZ2_bzBuffToBuffCompress(out.data(), &size, const_cast<char*>(in.data()),
                                     static_cast<unsigned>(in.size()), 9, 0, 0),
            BZ_OK);
  out.resize(size);
  return out;
}

TEST(ScanDat, PlainAndBzip2AndNodeLinesAreRead) {
  test::TempDir dir;
  const std::string text =
      "NODE 1 2 3 0 0 1.5707963267948966\n1 0 0\n2 0 0\nNODE 0 0 0 0 0 0\n0 1 0\n";
  writeText(dir.path() / "s.dat", text);
  writeText(dir.path() / "s.dat.bz2", bzip2(text));
  auto plain = readScanDat(dir.path() / "s.dat");
  auto packed = readScanDat(dir.path() / "s.dat.bz2");
  ASSERT_TRUE(plain && packed) << (plain ? packed.error().message : plain.error().message);
  ASSERT_EQ(plain->size(), 2U);
  EXPECT_EQ((*plain)[0].points, (*packed)[0].points);
  EXPECT_EQ((*plain)[0].points.size(), 2U);
  const PointCloud world = (*plain)[0].pointsWorld();
  EXPECT_NEAR(world[0].x(), 1.0, 1e-6);  // rotated 90 degrees about z, then shifted
  EXPECT_NEAR(world[0].y(), 3.0, 1e-6);
  EXPECT_EQ((*plain)[0].originWorld(), Point3f(1, 2, 3));
}

TEST(ScanDat, BrokenTextAndCorruptBzip2AreErrors) {
  test::TempDir dir;
  writeText(dir.path() / "b.dat", "1 2 3\n4 five 6\n");
  auto bad = readScanDat(dir.path() / "b.dat");
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("line 2"), std::string::npos);
  std::string packed = bzip2(std::string(5000, '7'));
  writeText(dir.path() / "c.dat.bz2", packed.substr(0, packed.size() / 2));
  auto corrupt = readScanDat(dir.path() / "c.dat.bz2");
  ASSERT_FALSE(corrupt);
  EXPECT_NE(corrupt.error().message.find("bzip2"), std::string::npos);
}

/// Peak resident memory of this process so far, KiB.
long peakRssKb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss;
}

TEST(ScanDat, ABzip2BombIsRefusedAtItsFirstChunkInBoundedMemory) {
  test::TempDir dir;
  // 256 MiB of zeros compress to a few hundred bytes; bzip2 them in pieces (one buffer of 256
  // MiB would itself raise the peak this test watches).
  std::string packed;
  {
    bz_stream bz{};
    ASSERT_EQ(BZ2_bzCompressInit(&bz, 9, 0, 0), BZ_OK);
    std::vector<char> zeros(1 << 20, '\0'), out(1 << 16);
    for (int mib = 0; mib <= 256; ++mib) {
      bz.next_in = zeros.data();
      bz.avail_in = mib < 256 ? static_cast<unsigned>(zeros.size()) : 0;
      const int action = mib < 256 ? BZ_RUN : BZ_FINISH;
      int rc;
      do {
        bz.next_out = out.data();
        bz.avail_out = static_cast<unsigned>(out.size());
        rc = BZ2_bzCompress(&bz, action);
        packed.append(out.data(), out.size() - bz.avail_out);
      } while ((action == BZ_RUN && bz.avail_in > 0) ||
               (action == BZ_FINISH && rc != BZ_STREAM_END));
    }
    BZ2_bzCompressEnd(&bz);
  }
  ASSERT_LT(packed.size(), 100'000U);
  writeText(dir.path() / "bomb.dat.bz2", packed);
  const long before = peakRssKb();
  auto bomb = readScanDat(dir.path() / "bomb.dat.bz2");
  ASSERT_FALSE(bomb);
  EXPECT_NE(bomb.error().message.find("NUL byte"), std::string::npos) << bomb.error().message;
  EXPECT_LT(peakRssKb() - before, 16 * 1024) << "the reader held the expanded file";
  // Text without a line end for longer than a line may be: refused at the limit.
  writeText(dir.path() / "long.dat.bz2", bzip2(std::string(200'000, '7')));
  auto long_line = readScanDat(dir.path() / "long.dat.bz2");
  ASSERT_FALSE(long_line);
  EXPECT_NE(long_line.error().message.find("line 1 is longer than 65536 bytes"), std::string::npos)
      << long_line.error().message;
}

TEST(TextLines, SplitsAsGetlineDoesWithCrLfAndALastLineWithoutEnd) {
  test::TempDir dir;
  // Lines around the reader's 64 KiB chunks: one crosses a chunk border.
  std::string text = "a\r\n\nb c\n" + std::string(70'000, 'x') + "\n" + "last";
  for (const std::string name : {"t.txt", "t.txt.bz2"}) {
    writeText(dir.path() / name, name.ends_with(".bz2") ? bzip2(text) : text);
    auto lines = TextLines::open(dir.path() / name, 100'000);
    ASSERT_TRUE(lines);
    std::vector<std::string> got;
    for (;;) {
      auto next = lines->next();
      ASSERT_TRUE(next) << next.error().message;
      if (!*next) break;
      got.push_back(**next);
    }
    ASSERT_EQ(got.size(), 5U) << name;
    EXPECT_EQ(got[0], "a");
    EXPECT_EQ(got[1], "");
    EXPECT_EQ(got[2], "b c");
    EXPECT_EQ(got[3], std::string(70'000, 'x'));
    EXPECT_EQ(got[4], "last");
    EXPECT_EQ(lines->lineNumber(), 5U);
  }
  EXPECT_FALSE(TextLines::open(dir.path()));
  EXPECT_FALSE(TextLines::open(dir.path() / "missing.txt"));
}

}  // namespace
}  // namespace densemap
