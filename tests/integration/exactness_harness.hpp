#pragma once

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <memory>
#include <string>
#include <vector>

#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/raycast/integrator.hpp"

namespace densemap::test {

struct WorldScan {
  PointCloud points;
  Point3f origin;
};

inline std::vector<WorldScan> loadWorldScans(const ScanSource& source, std::size_t first,
                                             std::size_t count) {
  std::vector<WorldScan> scans;
  for (std::size_t i = first; i < std::min(source.size(), first + count); ++i) {
    auto scan = source.load(i);
    EXPECT_TRUE(scan) << scan.error().message;
    if (!scan) break;
    scans.push_back({scan->pointsWorld(), scan->originWorld()});
  }
  return scans;
}

/// Integrates the scans with OctoMap (the oracle) and with the raycast integrator on both
/// backends at 1 and 2 threads; asserts every map equals OctoMap's, cell for cell, after every
/// `check_every`-th scan and after the last.
inline void expectRaycastEqualsOctomap(const std::vector<WorldScan>& scans, double resolution,
                                       double max_range, std::size_t check_every = 1) {
  ASSERT_FALSE(scans.empty());
  OctreeMap oracle(resolution, SensorModel{});
  struct Subject {
    std::string name;
    std::unique_ptr<OccupancyMap> map;
    std::unique_ptr<tbb::task_arena> arena;
    Integrator integrator;
  };
  std::vector<Subject> subjects;
  for (const Backend backend : {Backend::kGrid, Backend::kOctree}) {
    for (const int threads : {1, 2}) {
      subjects.push_back({std::string(backendName(backend)) + "/" + std::to_string(threads) + "t",
                          std::move(*makeMap(backend, resolution)),
                          std::make_unique<tbb::task_arena>(threads),
                          Integrator({.max_range_m = max_range})});
    }
  }
  for (std::size_t i = 0; i < scans.size(); ++i) {
    oracle.insertWithOctomap(scans[i].points, scans[i].origin, max_range);
    for (Subject& s : subjects) {
      s.arena->execute([&] { s.integrator.integrate(*s.map, scans[i].points, scans[i].origin); });
    }
    if ((i + 1) % check_every != 0 && i + 1 != scans.size()) continue;
    for (const Subject& s : subjects) {
      const MapDiff d = diffMaps(*s.map, oracle);
      ASSERT_EQ(d.differing(), 0U)
          << s.name << " after scan " << i << ": " << d.only_in_a << " cells only ours, "
          << d.only_in_b << " only OctoMap's, " << d.value_mismatch << " values differ";
    }
  }
  EXPECT_GT(oracle.knownCells(), 0U);
}

}  // namespace densemap::test
