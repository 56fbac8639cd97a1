#pragma once
// Runs densemap-map and OctoMap's own tools (graph2tree, log2graph, compare_octrees) on the same
// input and compares the trees cell for cell. DENSEMAP_MAP_BIN and the tools' paths come from
// the build (tests/integration/CMakeLists.txt).
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <sstream>

#include "densemap/io/octomap_export.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap::test {

namespace fs = std::filesystem;
struct ToolRun {
  int status = -1;
  std::string output;
};

/// Runs a shell command; stdout and stderr together.
inline ToolRun runTool(const std::string& command) {
  ToolRun r;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return r;
  std::array<char, 4096> buffer{};
  std::size_t n = 0;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0)
    r.output.append(buffer.data(), n);
  r.status = ::pclose(pipe);
  return r;
}

inline std::string shellQuoted(const fs::path& p) { return "'" + p.string() + "'"; }

inline std::string number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

#define DENSEMAP_REQUIRE_TOOL(path)                                                    \
  if (std::string(path).empty() || !std::filesystem::exists(path))                     \
  GTEST_SKIP() << "OctoMap's tools (Debian package octomap-tools) are not installed: " \
               << "scripts/install-deps.sh installs them"

/// graph2tree and densemap-map on the same input give the same tree.
inline void expectSameTree(const fs::path& graph, const fs::path& densemap_input, double resolution,
                           double max_range, const fs::path& dir, std::size_t min_cells) {
  SCOPED_TRACE(graph.filename().string() + " at " + number(resolution) + " m");
  const fs::path reference = dir / "graph2tree.bt";
  const fs::path ours = dir / "densemap.ot";
  const ToolRun g =
      runTool(std::string(DENSEMAP_GRAPH2TREE) + " -i " + shellQuoted(graph) + " -o " +
              shellQuoted(reference) + " -res " + number(resolution) + " -m " + number(max_range));
  ASSERT_EQ(g.status, 0) << g.output;
  const ToolRun d =
      runTool(std::string(DENSEMAP_MAP_BIN) + " --data " + shellQuoted(densemap_input) + " --out " +
              shellQuoted(ours) + " --resolution " + number(resolution) + " --max-range " +
              number(max_range));
  ASSERT_EQ(d.status, 0) << d.output;

  auto a = importOctomap(fs::path(reference.string() + ".ot"), Backend::kGrid);
  auto b = importOctomap(ours, Backend::kGrid);
  ASSERT_TRUE(a) << a.error().message;
  ASSERT_TRUE(b) << b.error().message;
  EXPECT_GE((*a)->knownCells(), min_cells);
  const MapDiff diff = diffMaps(**a, **b);
  std::printf("graph2tree vs densemap-map: %s at %s m, range %s: %zu cells, %zu differing\n",
              graph.filename().c_str(), number(resolution).c_str(), number(max_range).c_str(),
              diff.union_cells, diff.differing());
  EXPECT_EQ(diff.differing(), 0U) << "only graph2tree: " << diff.only_in_a
                                  << ", only densemap: " << diff.only_in_b
                                  << ", other log-odds: " << diff.value_mismatch << " of "
                                  << diff.union_cells;

  const ToolRun c = runTool(std::string(DENSEMAP_COMPARE_OCTREES) + " " +
                            shellQuoted(reference.string() + ".ot") + " " + shellQuoted(ours));
  EXPECT_EQ(c.status, 0) << c.output;
  EXPECT_NE(c.output.find("KLD: 0\n"), std::string::npos) << c.output;
}

/// Writes `source`'s scans [first, first + count) as a .graph with densemap-map.
inline fs::path saveGraph(const fs::path& data, std::size_t first, std::size_t count,
                          const fs::path& out) {
  const ToolRun r = runTool(std::string(DENSEMAP_MAP_BIN) + " --data " + shellQuoted(data) +
                            " --first " + std::to_string(first) + " --limit " +
                            std::to_string(count) + " --save-graph " + shellQuoted(out));
  EXPECT_EQ(r.status, 0) << r.output;
  return out;
}

inline fs::path octomapExample(const std::string& name) {
  const fs::path installed = fs::path("/usr/share/doc/liboctomap-dev/examples/data") / name;
  if (fs::exists(installed)) return installed;
  return sharedData("octomap/" + name).value_or(fs::path());
}

}  // namespace densemap::test
