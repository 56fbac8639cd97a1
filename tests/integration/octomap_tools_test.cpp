// densemap-map against OctoMap's own command-line tools (Debian's octomap-tools): for OctoMap's
// inputs (.graph, scan.dat) both build the same tree, cell for cell and log-odds for log-odds.
// graph2tree's full-probability tree (`T.ot`) and densemap-map's `.ot` are read back with OctoMap
// and diffed over the union of their cells; compare_octrees must agree (same size, KLD 0).
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/sim/sequence.hpp"
#include "octomap_tools_harness.hpp"

namespace densemap {
namespace {

using test::expectSameTree;
using test::octomapExample;
using test::runTool;
using test::saveGraph;
using test::shellQuoted;
using test::ToolRun;
namespace fs = std::filesystem;

TEST(Graph2tree, SimulatedScansAsAGraph) {
  DENSEMAP_REQUIRE_TOOL(DENSEMAP_GRAPH2TREE);
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 900;
  o.scans = 5;
  o.seed = 7;
  o.ground_truth_resolution_m = 0;
  ASSERT_TRUE(writeSimulatedSequence(o, dir.path() / "sim"));
  // Sensor-frame scans with rotated, translated poses: the rounding graph2tree does matters.
  const fs::path graph = saveGraph(dir.path() / "sim", 0, 5, dir.path() / "sim.graph");
  expectSameTree(graph, graph, 0.1, 12.0, dir.path(), 10000);
  expectSameTree(graph, graph, 0.05, -1.0, dir.path(), 10000);
}

TEST(Graph2tree, ScanDatWithNodeLinesAsLog2graphReadsIt) {
  DENSEMAP_REQUIRE_TOOL(DENSEMAP_LOG2GRAPH);
  test::TempDir dir;
  // Three nodes at rotated poses; a line that starts with a space is skipped by both readers.
  std::ofstream dat(dir.path() / "scans.dat");
  dat << "# three scans\n";
  for (int n = 0; n < 3; ++n) {
    dat << "NODE " << 0.31 * n << " " << -1.7 + 0.2 * n << " 0.43 0.05 " << -0.02 * n << " "
        << 0.7 * n + 0.1 << "\n";
    if (n == 1) dat << " 100 100 100\n";
    for (int i = 0; i < 4000; ++i) {
      const double a = 0.0015707963 * i * (n + 1);
      dat << 6.3 * std::cos(a) + 0.001 * i << " " << 4.1 * std::sin(3 * a) << " "
          << -0.9 + 0.00071 * i << "\n";
    }
  }
  dat.close();
  const fs::path graph = dir.path() / "scans.graph";
  const ToolRun l = runTool(std::string(DENSEMAP_LOG2GRAPH) + " " +
                            shellQuoted(dir.path() / "scans.dat") + " " + shellQuoted(graph));
  ASSERT_EQ(l.status, 0) << l.output;
  expectSameTree(graph, dir.path() / "scans.dat", 0.05, 9.0, dir.path(), 5000);
}

TEST(Graph2tree, OctomapSphericalScanAndScanDat) {
  DENSEMAP_REQUIRE_TOOL(DENSEMAP_GRAPH2TREE);
  const fs::path spherical = octomapExample("spherical_scan.graph");
  const fs::path scan_dat = octomapExample("scan.dat.bz2");
  if (spherical.empty() || scan_dat.empty()) {
    GTEST_SKIP() << "OctoMap's example data (liboctomap-dev's examples/data) not found";
  }
  test::TempDir dir;
  expectSameTree(spherical, spherical, 0.1, -1.0, dir.path(), 10000);
  // OctoMap's scan.dat is one scan without a NODE line, which OctoMap's reader refuses and
  // densemap reads as a scan at the origin: give OctoMap the identity NODE line it needs.
  auto text = readFileBytes(scan_dat);
  ASSERT_TRUE(text) << text.error().message;
  std::ofstream(dir.path() / "scan.dat") << "NODE 0 0 0 0 0 0\n" << *text;
  const ToolRun l =
      runTool(std::string(DENSEMAP_LOG2GRAPH) + " " + shellQuoted(dir.path() / "scan.dat") + " " +
              shellQuoted(dir.path() / "scan.graph"));
  ASSERT_EQ(l.status, 0) << l.output;
  expectSameTree(dir.path() / "scan.graph", scan_dat, 0.2, 20.0, dir.path(), 10000);
}

}  // namespace
}  // namespace densemap
