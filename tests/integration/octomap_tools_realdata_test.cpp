// graph2tree against densemap-map on real scans (label realdata): the AKIMap authors' sample
// graph, and 40 BALM scans converted to a graph, at 0.1 and 0.2 m.
#include <gtest/gtest.h>

#include "octomap_tools_harness.hpp"

namespace densemap {
namespace {

using test::expectSameTree;
using test::saveGraph;
namespace fs = std::filesystem;

TEST(Graph2tree, AkimapSampleGraph) {
  DENSEMAP_REQUIRE_TOOL(DENSEMAP_GRAPH2TREE);
  DENSEMAP_REQUIRE_DATA(graph, "akimap-sample/akimap_sample.graph");
  test::TempDir dir;
  expectSameTree(graph, graph, 0.1, 30.0, dir.path(), 100000);
  expectSameTree(graph, graph, 0.2, 30.0, dir.path(), 20000);
}

TEST(Graph2tree, BalmScansConvertedToAGraph) {
  DENSEMAP_REQUIRE_TOOL(DENSEMAP_GRAPH2TREE);
  DENSEMAP_REQUIRE_DATA(balm, "balm-realworld");
  test::TempDir dir;
  const fs::path graph = saveGraph(balm, 0, 40, dir.path() / "balm.graph");
  expectSameTree(graph, graph, 0.2, 15.0, dir.path(), 300000);
  expectSameTree(graph, graph, 0.1, 15.0, dir.path(), 1000000);
}

}  // namespace
}  // namespace densemap
