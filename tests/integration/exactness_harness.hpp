#pragma once

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/parallel/tbb_runner.hpp"
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

/// One integration set-up the harness holds to the reference.
struct MethodCase {
  IntegrationMethod method;
  UpdateRule rule;
  Backend backend;
  int threads;
};

/// Every method on the grid backend at 2 threads under both rules, plus super rays + culling
/// (the server's default) on the octree backend and at 1 thread.
inline std::vector<MethodCase> standardCases() {
  std::vector<MethodCase> cases;
  for (const UpdateRule rule : {UpdateRule::kSet, UpdateRule::kPerRay}) {
    for (const IntegrationMethod m :
         {IntegrationMethod::kRaycast, IntegrationMethod::kSuperRay, IntegrationMethod::kCulling,
          IntegrationMethod::kSuperRayCulling}) {
      cases.push_back({m, rule, Backend::kGrid, 2});
    }
    cases.push_back({IntegrationMethod::kSuperRayCulling, rule, Backend::kOctree, 2});
    cases.push_back({IntegrationMethod::kSuperRayCulling, rule, Backend::kGrid, 1});
  }
  return cases;
}

inline CellChanges sortedChanges(CellChanges c) {
  std::sort(c.begin(), c.end(), [](const CellChange& a, const CellChange& b) {
    return a.key.packed() < b.key.packed();
  });
  return c;
}

/// Integrates the scans with OctoMap (the oracle) and with every case. After EVERY scan each
/// case's changes must equal those of plain raycast on the grid under the same rule (same map
/// before + same changes = same map after), and the raycast maps must equal: under kSet,
/// OctoMap's map (checked with a full diff after every `check_every`-th scan and the last);
/// every map is diffed in full against its reference after the last scan.
/// Also asserts that super rays and culling did something when `expect_savings`.
inline void expectMethodsAgree(const std::vector<WorldScan>& scans, double resolution,
                               double max_range, std::size_t check_every = 1,
                               const std::vector<MethodCase>& cases = standardCases(),
                               bool expect_savings = true) {
  ASSERT_FALSE(scans.empty());
  OctreeMap oracle(resolution, SensorModel{});
  struct Subject {
    MethodCase c;
    std::string name;
    std::unique_ptr<OccupancyMap> map;
    std::unique_ptr<tbb::task_arena> arena;
    Integrator integrator;
    std::size_t super_rays = 0, culled = 0;
  };
  std::vector<Subject> subjects;
  std::vector<MethodCase> all;
  // References first: raycast on the grid at 2 threads, one per rule.
  for (const UpdateRule rule : {UpdateRule::kSet, UpdateRule::kPerRay}) {
    all.push_back({IntegrationMethod::kRaycast, rule, Backend::kGrid, 2});
  }
  all.insert(all.end(), cases.begin(), cases.end());
  subjects.reserve(all.size());
  for (const MethodCase& c : all) {
    const std::string name =
        std::string(methodName(c.method)) + "/" + std::string(ruleName(c.rule)) + "/" +
        std::string(backendName(c.backend)) + "/" + std::to_string(c.threads) + "t";
    subjects.push_back(
        {c, name, std::move(*makeMap(c.backend, resolution)),
         std::make_unique<tbb::task_arena>(c.threads),
         Integrator({.method = c.method, .rule = c.rule, .max_range_m = max_range})});
  }
  const auto referenceFor = [&](UpdateRule rule) -> const Subject& {
    return subjects[rule == UpdateRule::kSet ? 0 : 1];
  };
  for (Subject& s : subjects) s.map->setRunner(tbbRunner());  // as the engine's: in the arena
  std::vector<CellChanges> changes(subjects.size());
  for (std::size_t i = 0; i < scans.size(); ++i) {
    oracle.insertWithOctomap(scans[i].points, scans[i].origin, max_range);
    for (std::size_t j = 0; j < subjects.size(); ++j) {
      Subject& s = subjects[j];
      changes[j].clear();
      s.arena->execute([&] {
        const ScanStats st =
            s.integrator.integrate(*s.map, scans[i].points, scans[i].origin, &changes[j]);
        s.super_rays += st.super_rays;
        s.culled += st.culled;
      });
      changes[j] = sortedChanges(std::move(changes[j]));
    }
    for (std::size_t j = 2; j < subjects.size(); ++j) {
      const Subject& s = subjects[j];
      const std::size_t r = s.c.rule == UpdateRule::kSet ? 0 : 1;
      const CellChanges& mine = changes[j];
      const CellChanges& ref = changes[r];
      ASSERT_EQ(mine.size(), ref.size()) << s.name << ": changed cells in scan " << i;
      for (std::size_t k = 0; k < mine.size(); ++k) {
        ASSERT_TRUE(mine[k].key == ref[k].key && mine[k].log_odds == ref[k].log_odds)
            << s.name << ": scan " << i << " change " << k;
      }
    }
    if ((i + 1) % check_every == 0 || i + 1 == scans.size()) {
      const MapDiff d = diffMaps(*subjects[0].map, oracle);
      ASSERT_EQ(d.differing(), 0U)
          << "raycast after scan " << i << ": " << d.only_in_a << " cells only ours, "
          << d.only_in_b << " only OctoMap's, " << d.value_mismatch << " values differ";
    }
  }
  for (std::size_t j = 2; j < subjects.size(); ++j) {
    const Subject& s = subjects[j];
    const OccupancyMap& ref = s.c.rule == UpdateRule::kSet
                                  ? static_cast<const OccupancyMap&>(oracle)
                                  : *referenceFor(s.c.rule).map;
    EXPECT_EQ(diffMaps(*s.map, ref).differing(), 0U) << s.name << " at the end";
    if (!expect_savings) continue;
    if (s.c.method == IntegrationMethod::kSuperRay ||
        s.c.method == IntegrationMethod::kSuperRayCulling) {
      EXPECT_GT(s.super_rays, 0U) << s.name << " formed no super ray";
    }
    if (s.c.method == IntegrationMethod::kCulling ||
        s.c.method == IntegrationMethod::kSuperRayCulling) {
      EXPECT_GT(s.culled, 0U) << s.name << " culled nothing";
    }
  }
  // per_ray really differs from set somewhere (else the rule test would be vacuous).
  EXPECT_GT(diffMaps(*subjects[0].map, *subjects[1].map).differing(), 0U);
  EXPECT_GT(oracle.knownCells(), 0U);
}

}  // namespace densemap::test
