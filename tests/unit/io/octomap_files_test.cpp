#include <gtest/gtest.h>
#include <octomap/OcTree.h>
#include <octomap/ScanGraph.h>

#include <fstream>
#include <sstream>

#include "densemap/io/octomap_export.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

std::filesystem::path writeGraph(const std::filesystem::path& dir) {
  octomap::ScanGraph graph;
  for (int n = 0; n < 3; ++n) {
    auto* cloud = new octomap::Pointcloud();
    for (int i = 0; i < 100; ++i) cloud->push_back(0.1F * i, 0.5F * n, -0.3F * i);
    graph.addNode(cloud, octomap::pose6d(1.0 * n, 2, 3, 0.1, 0.2, 0.3 * n));
  }
  const auto path = dir / "g.graph";
  EXPECT_TRUE(graph.writeBinary(path.string()));
  return path;
}

TEST(ScanGraph, ReadsWhatOctomapWrites) {
  test::TempDir dir;
  const auto path = writeGraph(dir.path());
  octomap::ScanGraph expected;
  ASSERT_TRUE(expected.readBinary(path.string()));
  auto scans = readScanGraph(path);
  ASSERT_TRUE(scans) << scans.error().message;
  ASSERT_EQ(scans->size(), expected.size());
  for (std::size_t n = 0; n < scans->size(); ++n) {
    const octomap::ScanNode* node = expected.getNodeByID(static_cast<unsigned>(n));
    ASSERT_EQ((*scans)[n].points.size(), node->scan->size());
    for (std::size_t i = 0; i < node->scan->size(); ++i) {
      const auto& p = (*node->scan)[i];
      EXPECT_EQ((*scans)[n].points[i], Point3f(p.x(), p.y(), p.z()));
    }
    // World points and origin exactly as graph2tree computes them (float pose6d).
    octomap::Pointcloud world(*node->scan);
    world.transform(node->pose);
    const PointCloud ours = (*scans)[n].pointsWorld();
    ASSERT_EQ(ours.size(), world.size());
    for (std::size_t i = 0; i < world.size(); ++i) {
      EXPECT_EQ(ours[i], Point3f(world[i].x(), world[i].y(), world[i].z()));
    }
    const octomap::point3d o = node->pose.transform(node->pose.inv().transform(node->pose.trans()));
    EXPECT_EQ((*scans)[n].originWorld(), Point3f(o.x(), o.y(), o.z()));
    // The double pose is the same one.
    const octomap::point3d q = node->pose.transform(octomap::point3d(1, 2, 3));
    const Point3f mapped = (*scans)[n].T_world_sensor.cast<float>() * Point3f(1, 2, 3);
    EXPECT_NEAR(mapped.x(), q.x(), 1e-5);
    EXPECT_NEAR(mapped.y(), q.y(), 1e-5);
    EXPECT_NEAR(mapped.z(), q.z(), 1e-5);
  }
}

TEST(ScanGraph, WrittenGraphsAreReadByOctomapWithTheSameWorldPoints) {
  test::TempDir dir;
  // Sensor-frame scans with double poses, and world-frame scans with an origin.
  std::vector<Scan> scans(3);
  for (std::size_t n = 0; n < scans.size(); ++n) {
    scans[n].id = n;
    scans[n].frame = n == 2 ? PointFrame::kWorld : PointFrame::kSensor;
    scans[n].T_world_sensor = transformFromTranslationQuaternion(
        {0.5 * n, -1.25, 0.3}, std::cos(0.2 * n), 0, 0.1, std::sin(0.2 * n));
    for (int i = 0; i < 50; ++i) scans[n].points.emplace_back(0.2F * i, 1.0F + n, -0.1F * i);
  }
  const MemoryScanSource source(scans, "test scans");
  std::size_t reported = 0;
  ASSERT_TRUE(
      writeScanGraph(source, 0, 10, dir.path() / "w.graph", [&](std::size_t k) { reported = k; }));
  EXPECT_EQ(reported, 3U);
  octomap::ScanGraph graph;
  ASSERT_TRUE(graph.readBinary((dir.path() / "w.graph").string()));
  ASSERT_EQ(graph.size(), 3U);
  auto back = readScanGraph(dir.path() / "w.graph");
  ASSERT_TRUE(back) << back.error().message;
  for (std::size_t n = 0; n < scans.size(); ++n) {
    const PointCloud expected = scans[n].pointsWorld();
    const PointCloud got = (*back)[n].pointsWorld();
    ASSERT_EQ(got.size(), expected.size());
    for (std::size_t i = 0; i < got.size(); ++i) {
      EXPECT_NEAR((got[i] - expected[i]).norm(), 0.0, 1e-5) << "scan " << n << " point " << i;
    }
    EXPECT_NEAR(((*back)[n].originWorld() - scans[n].originWorld()).norm(), 0.0, 1e-6);
  }
  // A part of the source; a first scan past the end is an error.
  ASSERT_TRUE(writeScanGraph(source, 1, 1, dir.path() / "one.graph"));
  auto one = readScanGraph(dir.path() / "one.graph");
  ASSERT_TRUE(one);
  EXPECT_EQ(one->size(), 1U);
  EXPECT_EQ((*one)[0].points, scans[1].points);
  EXPECT_FALSE(writeScanGraph(source, 3, 1, dir.path() / "none.graph"));
}

// A node 1e30 m away wrote an empty map with exit 0.
TEST(ScanGraph, APoseBeyondAnyMapIsAClearError) {
  test::TempDir dir;
  octomap::ScanGraph graph;
  auto* cloud = new octomap::Pointcloud();
  cloud->push_back(1, 2, 3);
  graph.addNode(cloud, octomap::pose6d(1e30, 0, 0, 0, 0, 0));
  const auto path = dir.path() / "far.graph";
  ASSERT_TRUE(graph.writeBinary(path.string()));
  auto scans = readScanGraph(path);
  ASSERT_FALSE(scans);
  EXPECT_NE(scans.error().message.find("node 0"), std::string::npos) << scans.error().message;
}

TEST(ScanGraph, TruncatedFilesAreClearErrorsAtEveryLength) {
  test::TempDir dir;
  const auto path = writeGraph(dir.path());
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  // Every cut that removes part of a node must fail; cutting only the edge list may pass.
  const std::size_t edges_bytes = 4;
  for (std::size_t cut = 0; cut + edges_bytes < bytes.size(); cut += 37) {
    std::ofstream(dir.path() / "t.graph", std::ios::binary) << bytes.substr(0, cut);
    auto scans = readScanGraph(dir.path() / "t.graph");
    ASSERT_FALSE(scans) << "cut at " << cut;
    EXPECT_NE(scans.error().message.find("t.graph"), std::string::npos);
  }
  const std::uint32_t absurd = 0xFFFFFFFF;
  std::ofstream(dir.path() / "a.graph", std::ios::binary)
      << std::string(reinterpret_cast<const char*>(&absurd), 4) << std::string(100, '\0');
  EXPECT_FALSE(readScanGraph(dir.path() / "a.graph"));
}

// liboctomap's writeBinaryConst prints "Writing N nodes ... done." on stderr
// (a bare " done." in the server's log after every .bt save); ours writes the same bytes quietly.
TEST(OctomapExport, BinaryFilesAreOctomapsBytesWithNothingOnStderr) {
  octomap::OcTree tree(0.1);
  for (int i = 0; i < 200; ++i) {
    tree.updateNode(octomap::point3d(0.05F * i, -0.1F * (i % 13), 0.2F * (i % 5)), i % 3 != 0);
  }
  std::ostringstream theirs, ours;
  testing::internal::CaptureStderr();
  ASSERT_TRUE(tree.writeBinaryConst(theirs));
  (void)testing::internal::GetCapturedStderr();  // whatever this liboctomap prints
  testing::internal::CaptureStderr();
  ASSERT_TRUE(writeOctomapBinary(tree, ours));
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
  ASSERT_GT(ours.str().size(), 100U);
  EXPECT_EQ(ours.str(), theirs.str());
  std::istringstream in(ours.str());
  octomap::OcTree read(0.2);
  ASSERT_TRUE(read.readBinary(in));
  EXPECT_EQ(read.size(), tree.size());
}

TEST(OctomapExport, OtRoundTripsLogOddsAndBtRoundTripsOccupancy) {
  test::TempDir dir;
  GridMap grid(0.1, SensorModel{});
  Integrator integrator({.max_range_m = 5.0});
  for (int s = 0; s < 3; ++s) {
    const Point3f o(0.2F * s, 0, 0);
    integrator.integrate(grid, test::adversarialScan(0.1, o, 3000, 5.0, s), o);
  }
  ASSERT_TRUE(exportOctomap(grid, dir.path() / "m.ot"));
  ASSERT_TRUE(exportOctomap(grid, dir.path() / "m.bt"));
  EXPECT_FALSE(exportOctomap(grid, dir.path() / "m.png"));

  auto ot = importOctomap(dir.path() / "m.ot", Backend::kGrid);
  ASSERT_TRUE(ot) << ot.error().message;
  EXPECT_EQ(diffMaps(grid, **ot).differing(), 0U);

  auto bt = importOctomap(dir.path() / "m.bt", Backend::kOctree);
  ASSERT_TRUE(bt) << bt.error().message;
  std::size_t agree = 0, total = 0;
  grid.forEachKnown([&](const VoxelKey& k, float v) {
    ++total;
    const auto w = (*bt)->logOdds(k);
    if (w && SensorModel::isOccupied(*w) == SensorModel::isOccupied(v)) ++agree;
  });
  EXPECT_EQ(agree, total);
  EXPECT_EQ((*bt)->knownCells(), total);

  std::ofstream(dir.path() / "broken.bt") << "# Octomap OcTree binary file\nnonsense";
  EXPECT_FALSE(importOctomap(dir.path() / "broken.bt", Backend::kGrid));
}

}  // namespace
}  // namespace densemap
