#include "densemap/map/grid_map.hpp"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <tuple>

#include "densemap/map/map_diff.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"
#include "densemap/parallel/tbb_runner.hpp"

namespace densemap {
namespace {

ScanUpdate randomUpdate(std::mt19937& rng, double p_occupied, UpdateRule rule = UpdateRule::kSet) {
  std::uniform_int_distribution<int> coord(32700, 32830);
  std::bernoulli_distribution occ(p_occupied);
  std::uniform_int_distribution<std::uint32_t> weight(1, 6);
  ScanUpdate u(rule);
  for (int i = 0; i < 20000; ++i) {
    const VoxelKey k{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                     static_cast<std::uint16_t>(coord(rng) / 8 + 28600)};
    const std::uint32_t w = weight(rng);
    occ(rng) ? u.markOccupied(k, w) : u.markFree(k, w);
  }
  return u;
}

/// The fully-free masks a map reports equal "known and at the lower bound", cell by cell.
void expectFullyFreeMasksMatchValues(const OccupancyMap& map) {
  std::size_t from_masks = 0;
  std::vector<FullyFreeBlock> blocks;
  map.appendFullyFreeBlocks(block::BlockBox::all(), blocks);
  for (const auto& [block_key, mask] : blocks) {
    EXPECT_NE(block::countBits(mask), 0U) << "a block without fully-free cells";
    for (int i = 0; i < block::kVoxels; ++i) {
      if (!block::testBit(mask, i)) continue;
      ++from_masks;
      const auto v = map.logOdds(block::keyOf(block_key, i));
      ASSERT_TRUE(v.has_value());
      EXPECT_LE(*v, map.sensorModel().clampMin());
    }
  }
  std::size_t from_values = 0;
  map.forEachKnown([&](const VoxelKey&, float v) {
    if (map.sensorModel().isFullyFree(v)) ++from_values;
  });
  EXPECT_EQ(from_masks, from_values);
  EXPECT_GT(from_values, 0U);
}

TEST(SensorModel, DefaultsAreOctomapsLogOdds) {
  const SensorModel sut;
  const octomap::OcTree tree(0.1);
  EXPECT_EQ(sut.hit(), tree.getProbHitLog());
  EXPECT_EQ(sut.miss(), tree.getProbMissLog());
  EXPECT_EQ(sut.clampMin(), tree.getClampingThresMinLog());
  EXPECT_EQ(sut.clampMax(), tree.getClampingThresMaxLog());
  EXPECT_NEAR(sut.hit(), 0.85, 0.01);
  EXPECT_NEAR(sut.miss(), -0.4, 0.01);
  EXPECT_NEAR(sut.clampMin(), -2.0, 0.01);
  EXPECT_NEAR(sut.clampMax(), 3.5, 0.02);
}

TEST(SensorModel, UpdatesClampAtBothEnds) {
  const SensorModel sut;
  float v = 0.0F;
  for (int i = 0; i < 20; ++i) v = sut.update(v, true);
  EXPECT_EQ(v, sut.clampMax());
  for (int i = 0; i < 40; ++i) v = sut.update(v, false);
  EXPECT_EQ(v, sut.clampMin());
}

// The grid against the octree over many updates, its kSet writes in AVX-512 lanes, AVX2 lanes
// and a cell at a time (where the processor has them; limitLanes): the same map, counts and
// changes in each.
TEST(GridMap, MatchesTheOctreeBackendOverManyUpdates) {
  for (const int lanes : {512, 256, 0}) {
    SCOPED_TRACE("lanes " + std::to_string(lanes));
    std::mt19937 rng(11);
    GridMap grid(0.1, SensorModel{});
    grid.limitLanes(lanes);
    OctreeMap octree(0.1, SensorModel{});
    // The change lists too (the grid's kSet block writer makes its own): the same cells and
    // values as the octree's, whatever the order.
    const auto sorted = [](CellChanges c) {
      std::sort(c.begin(), c.end(), [](const CellChange& x, const CellChange& y) {
        return std::tie(x.key.x, x.key.y, x.key.z) < std::tie(y.key.x, y.key.y, y.key.z);
      });
      return c;
    };
    for (int scan = 0; scan < 12; ++scan) {
      const ScanUpdate u = randomUpdate(rng, scan % 3 == 0 ? 0.6 : 0.1);
      CellChanges from_grid, from_octree;
      const ApplyStats a = grid.apply(u, &from_grid);
      const ApplyStats b = octree.apply(u, &from_octree);
      EXPECT_EQ(a.updated_cells, b.updated_cells);
      EXPECT_EQ(a.changed_cells, b.changed_cells);
      EXPECT_EQ(from_grid.size(), a.changed_cells);
      const CellChanges g = sorted(from_grid), o = sorted(from_octree);
      ASSERT_EQ(g.size(), o.size());
      for (std::size_t i = 0; i < g.size(); ++i) {
        ASSERT_EQ(g[i].key, o[i].key) << "scan " << scan << ", change " << i;
        ASSERT_EQ(g[i].log_odds, o[i].log_odds) << "scan " << scan << ", change " << i;
        ASSERT_EQ(g[i].known, o[i].known);
      }
    }
    const MapDiff diff = diffMaps(grid, octree);
    EXPECT_EQ(diff.differing(), 0U);
    EXPECT_GT(diff.union_cells, 100000U);
    EXPECT_EQ(grid.knownCells(), octree.knownCells());
    expectFullyFreeMasksMatchValues(grid);
  }
}

TEST(GridMap, CellsAtOrBeyondTheBoundTheirUpdateMovesTowardKeepTheirValueAsInOctoMap) {
  // OctoMap's updateNode returns early for such a cell ("no change: node already at
  // threshold"), whatever its value: the kSet block writer leaves it too. Within the clamps the
  // octree backend (OctoMap's own updateNode) is the reference; beyond them (a map loaded with
  // other clamps) only the grid can hold the value (OctoMap's setNodeValue clamps it).
  GridMap grid(0.1, SensorModel{});
  OctreeMap octree(0.1, SensorModel{});
  const SensorModel model;
  const float within[] = {model.clampMin(), -0.3F, 0.3F, model.clampMax()};
  const float beyond[] = {model.clampMin() - 1.0F, model.clampMax() + 0.5F};
  ScanUpdate u(UpdateRule::kSet);
  std::vector<VoxelKey> keys;
  const auto add = [&](float v, bool hit) {
    const VoxelKey k{static_cast<std::uint16_t>(32768 + 3 * keys.size()), 32770, 32771};
    keys.push_back(k);
    grid.setLogOdds(k, v);
    octree.setLogOdds(k, v);
    if (hit) {
      u.markOccupied(k);
    } else {
      u.markFree(k);
    }
  };
  for (const float v : within) {
    add(v, false);
    add(v, true);
  }
  add(beyond[0], false);  // crossed below the lower bound
  add(beyond[0], true);
  add(beyond[1], true);  // hit above the upper bound
  add(beyond[1], false);
  grid.apply(u);
  octree.apply(u);
  for (std::size_t i = 0; i < 2 * std::size(within); ++i) {
    EXPECT_EQ(*grid.logOdds(keys[i]), *octree.logOdds(keys[i])) << "cell " << i;
  }
  const std::size_t b = 2 * std::size(within);
  EXPECT_EQ(*grid.logOdds(keys[b]), beyond[0]);
  EXPECT_EQ(*grid.logOdds(keys[b + 1]), model.update(beyond[0], true));
  EXPECT_EQ(*grid.logOdds(keys[b + 2]), beyond[1]);
  EXPECT_EQ(*grid.logOdds(keys[b + 3]), model.update(beyond[1], false));
  expectFullyFreeMasksMatchValues(grid);
}

TEST(OccupancyMaps, PerRayRuleIsTheSameOnBothBackendsAndSumsEveryRay) {
  std::mt19937 rng(12);
  GridMap grid(0.1, SensorModel{});
  OctreeMap octree(0.1, SensorModel{});
  for (int scan = 0; scan < 10; ++scan) {
    const ScanUpdate u = randomUpdate(rng, scan % 3 == 0 ? 0.6 : 0.1, UpdateRule::kPerRay);
    const ApplyStats a = grid.apply(u);
    const ApplyStats b = octree.apply(u);
    EXPECT_EQ(a.changed_cells, b.changed_cells);
  }
  EXPECT_EQ(diffMaps(grid, octree).differing(), 0U);
  expectFullyFreeMasksMatchValues(grid);
  expectFullyFreeMasksMatchValues(octree);

  // One cell by hand: 2 hits and 3 misses in one scan move it by 2 l_occ + 3 l_free, once.
  GridMap one(0.1, SensorModel{});
  ScanUpdate u(UpdateRule::kPerRay);
  const VoxelKey k{32768, 32768, 32768};
  u.markOccupied(k, 2);
  u.markFree(k, 3);
  one.apply(u);
  const SensorModel m;
  EXPECT_EQ(*one.logOdds(k), static_cast<float>(2.0 * m.hit() + 3.0 * m.miss()));
  for (int i = 0; i < 9; ++i) one.apply(u);  // +0.48 per scan
  EXPECT_EQ(*one.logOdds(k), m.clampMax());  // clamped
}

TEST(OccupancyMaps, FullyFreeMasksFollowUpdatesSetsAndClears) {
  std::mt19937 rng(4);
  GridMap grid(0.1, SensorModel{});
  OctreeMap octree(0.1, SensorModel{});
  for (int scan = 0; scan < 8; ++scan) {
    const ScanUpdate u = randomUpdate(rng, scan == 5 ? 0.5 : 0.05);
    grid.apply(u);
    octree.apply(u);
  }
  grid.setLogOdds(VoxelKey{32768, 32768, 28600 + 4090}, -2.0F);
  octree.setLogOdds(VoxelKey{32768, 32768, 28600 + 4090}, -2.0F);
  const VoxelKey lo{32720, 32720, 32690}, hi{32760, 32800, 32700};
  grid.clearBox(lo, hi);
  octree.clearBox(lo, hi);
  expectFullyFreeMasksMatchValues(grid);
  expectFullyFreeMasksMatchValues(octree);
}

/// The fully-free blocks `map` reports in `box`: block key -> mask.
std::map<std::uint64_t, block::BlockMask> fullyFreeIn(const OccupancyMap& map,
                                                      const block::BlockBox& box) {
  std::map<std::uint64_t, block::BlockMask> out;
  std::vector<FullyFreeBlock> blocks;
  map.appendFullyFreeBlocks(box, blocks);
  for (const auto& [key, mask] : blocks) {
    EXPECT_TRUE(out.emplace(key, mask).second) << "block " << key << " reported twice";
  }
  return out;
}

// countBits takes the POPCNT instruction where the processor has it; every variant
// counts what a bit-by-bit loop counts.
TEST(BlockLayout, CountBitsEqualsABitByBitCount) {
  std::mt19937_64 rng(7);
  std::vector<std::uint64_t> words(70);
  for (std::size_t n = 0; n <= words.size(); ++n) {
    for (auto& w : words) w = rng() & rng();  // about a quarter of the bits set
    if (n > 2) words[1] = ~std::uint64_t{0};
    std::size_t expected = 0;
    for (std::size_t i = 0; i < n; ++i) {
      for (int b = 0; b < 64; ++b) expected += (words[i] >> b) & 1U;
    }
    EXPECT_EQ(block::countBits(words.data(), n), expected) << n;
    EXPECT_EQ(block::detail::countBitsPortable(words.data(), n), expected) << n;
#if defined(__x86_64__) && defined(__GNUC__)
    if (block::detail::hasPopcnt()) {
      EXPECT_EQ(block::detail::countBitsPopcnt(words.data(), n), expected) << n;
    }
#endif
  }
  block::BlockMask m{};
  block::setBit(m, 0);
  block::setBit(m, 511);
  block::setBit(m, 200);
  EXPECT_EQ(block::countBits(m), 3U);
}

// The kernel map's free stage takes a voxel's block and cell straight from its packed key: the
// same as through the key, at every bit of every axis (the edges 0 and 65535 among them).
TEST(BlockLayout, BlockAndCellOfAPackedKeyAreThoseOfItsKey) {
  std::mt19937_64 rng(11);
  std::vector<VoxelKey> keys = {{0, 0, 0}, {65535, 65535, 65535}, {7, 8, 65528}, {32768, 32767, 1}};
  for (int i = 0; i < 100000; ++i) {
    const std::uint64_t r = rng();
    keys.push_back({static_cast<std::uint16_t>(r), static_cast<std::uint16_t>(r >> 16),
                    static_cast<std::uint16_t>(r >> 32)});
  }
  for (const VoxelKey& k : keys) {
    ASSERT_EQ(block::blockOfPacked(k.packed()), block::blockOf(k))
        << k.x << " " << k.y << " " << k.z;
    ASSERT_EQ(block::indexOfPacked(k.packed()), block::indexOf(k))
        << k.x << " " << k.y << " " << k.z;
  }
}

TEST(OccupancyMaps, FullyFreeBlocksInABoxAreTheWholeMapsBlocksInsideIt) {
  // The culling region asks for the blocks of its box; the grid answers from its
  // region index, whatever the box's size against the map's.
  std::mt19937 rng(31);
  GridMap grid(0.1, SensorModel{});
  OctreeMap octree(0.1, SensorModel{});
  for (int scan = 0; scan < 8; ++scan) {
    const ScanUpdate u = randomUpdate(rng, 0.05);
    grid.apply(u);
    octree.apply(u);
  }
  // Blocks far from the others (other regions) and a block dropped.
  grid.setLogOdds(VoxelKey{1000, 2000, 3000}, -3.0F);
  octree.setLogOdds(VoxelKey{1000, 2000, 3000}, -3.0F);
  grid.setLogOdds(VoxelKey{60000, 200, 32768}, -3.0F);  // then dropped (the grid only)
  ASSERT_EQ(grid.evictBlocks([](const Point3f& c) { return c.x() < 2000.0F; }).blocks, 1U);
  const auto all_grid = fullyFreeIn(grid, block::BlockBox::all());
  const auto all_octree = fullyFreeIn(octree, block::BlockBox::all());
  ASSERT_GT(all_grid.size(), 5U);
  for (const auto& [key, mask] : all_grid) EXPECT_NE(block::countBits(mask), 0U) << key;
  EXPECT_EQ(all_grid, all_octree);
  const auto inside = [](const std::map<std::uint64_t, block::BlockMask>& blocks,
                         const block::BlockBox& box) {
    std::map<std::uint64_t, block::BlockMask> out;
    for (const auto& [key, mask] : blocks) {
      if (box.contains(key)) out.emplace(key, mask);
    }
    return out;
  };
  std::uniform_int_distribution<std::uint32_t> centre(4080, 4105), half(0, 12);
  const std::uint32_t far[3] = {125, 250, 375};  // the lone block's coordinates (key / 8)
  std::size_t found = 0;
  for (int trial = 0; trial < 300; ++trial) {
    block::BlockBox box;
    for (int a = 0; a < 3; ++a) {
      const std::uint32_t c = trial % 10 == 0 ? far[a] : centre(rng), h = half(rng);
      box.min[a] = c - h;
      box.max[a] = c + h;
    }
    const auto expected = inside(all_grid, box);
    ASSERT_EQ(fullyFreeIn(grid, box), expected) << "trial " << trial;
    ASSERT_EQ(fullyFreeIn(octree, box), inside(all_octree, box)) << "trial " << trial;
    found += expected.size();
  }
  EXPECT_GT(found, 100U);  // the boxes met the map (302 blocks with fully-free cells)
}

// Eviction passes over whole regions of 8^3 blocks whose corners are kept: against the plain
// rule (a block stays exactly when its centre is kept), for windows (ball and box, and both)
// that cut through regions, hold some whole and reject others whole.
TEST(GridMap, EvictionKeepsExactlyTheBlocksWhoseCentresAreKept) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(32768 - 400, 32768 + 400);  // 80 m at 0.1 m
  for (int trial = 0; trial < 12; ++trial) {
    GridMap grid(0.1, SensorModel{});
    std::vector<std::uint64_t> blocks;
    for (int i = 0; i < 4000; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng) / 4 + 3 * 32768 / 4)};
      grid.setLogOdds(k, 1.0F);
      blocks.push_back(block::blockOf(k));
    }
    std::sort(blocks.begin(), blocks.end());
    blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
    std::uniform_real_distribution<float> centre(-30.0F, 30.0F), radius(5.0F, 40.0F);
    const Point3f origin(centre(rng) / 2, centre(rng) / 2, centre(rng) / 4);
    const float r = radius(rng);
    const Point3f lo(centre(rng) - 20.0F, -25.0F, -40.0F), hi(lo.x() + 35.0F, 25.0F, 40.0F);
    const int shape = trial % 3;  // ball, box, both
    const auto keep = [&](const Point3f& c) {
      if (shape != 1 && (c - origin).cast<double>().squaredNorm() > double(r) * r) return false;
      if (shape != 0) return (c.array() >= lo.array()).all() && (c.array() <= hi.array()).all();
      return true;
    };
    std::size_t expected_blocks = 0;
    for (const std::uint64_t b : blocks) {
      expected_blocks += keep(block::centreOf(grid.grid(), b)) ? 0 : 1;
    }
    const EvictStats stats = grid.evictBlocks(keep);
    EXPECT_EQ(stats.blocks, expected_blocks) << "trial " << trial;
    std::size_t kept = 0;
    for (const std::uint64_t b : blocks) {
      bool any = false;
      for (int c = 0; c < block::kVoxels && !any; ++c) {
        any = grid.logOdds(block::keyOf(b, c)).has_value();
      }
      ASSERT_EQ(any, keep(block::centreOf(grid.grid(), b))) << "trial " << trial << " block " << b;
      kept += any ? 1 : 0;
    }
    EXPECT_GT(kept, 0U) << "trial " << trial;
    EXPECT_GT(expected_blocks, 0U) << "trial " << trial;
  }
}

TEST(GridMap, OneAndTwoThreadsGiveTheSameMap) {
  GridMap one(0.2, SensorModel{}), two(0.2, SensorModel{});
  one.setRunner(tbbRunner());  // TBB's chunks in arenas of 1 and 2 threads
  two.setRunner(tbbRunner());
  std::mt19937 rng_a(3), rng_b(3);
  tbb::task_arena arena1(1), arena2(2);
  for (int scan = 0; scan < 6; ++scan) {
    const ScanUpdate ua = randomUpdate(rng_a, 0.3);
    const ScanUpdate ub = randomUpdate(rng_b, 0.3);
    arena1.execute([&] { one.apply(ua); });
    arena2.execute([&] { two.apply(ub); });
  }
  EXPECT_EQ(diffMaps(one, two).differing(), 0U);
}

// assignBlocks (how a dense map's grid follows its evidence) against setLogOdds and erase cell
// by cell: the same map and the same changes, on 1 and 2 threads, in AVX-512 lanes, AVX2 lanes
// and a cell at a time (where the processor has them); an unchanged cell is neither written
// nor reported, so a version whose values did not change writes no block; a NaN forgets its
// cell.
TEST(GridMap, AssignBlocksEqualsSettingCellByCellAndSkipsUnchangedCells) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(32700, 32790);
  std::uniform_real_distribution<float> value(-3.0F, 3.0F);
  std::bernoulli_distribution nan_cell(0.01);
  GridMap plain(0.2, SensorModel{});
  constexpr std::array<int, 3> kLanes{512, 256, 0};
  std::vector<std::unique_ptr<GridMap>> maps;
  for (std::size_t m = 0; m < 2 * kLanes.size(); ++m) {
    maps.push_back(std::make_unique<GridMap>(0.2, SensorModel{}));
    maps.back()->setRunner(tbbRunner());
    maps.back()->limitLanes(kLanes[m / 2]);
  }
  std::map<std::uint64_t, BlockCells> by_block;
  std::map<std::uint64_t, float> wanted;  // packed key -> value
  std::vector<VoxelKey> set_before;       // round 0's cells
  for (int round = 0; round < 4; ++round) {
    if (round < 3) {  // round 3 repeats round 2's cells and values: nothing changes
      by_block.clear();
      wanted.clear();
      const auto want = [&](const VoxelKey& k, float v) {
        BlockCells& b = by_block[block::blockOf(k)];
        b.key = block::blockOf(k);
        block::setBit(b.cells, block::indexOf(k));
        wanted[k.packed()] = v;
      };
      for (int i = 0; i < 3000; ++i) {
        const VoxelKey k{static_cast<std::uint16_t>(coord(rng)),
                         static_cast<std::uint16_t>(coord(rng)),
                         static_cast<std::uint16_t>(coord(rng))};
        want(k, value(rng));
        if (round == 0) set_before.push_back(k);
      }
      // Round 1 forgets a few of round 0's cells (NaN): their blocks take the cell-by-cell path.
      if (round == 1) {
        for (const VoxelKey& k : set_before) {
          if (nan_cell(rng)) want(k, std::nanf(""));
        }
      }
    }
    std::vector<BlockCells> blocks;
    for (const auto& [key, b] : by_block) blocks.push_back(b);
    CellChanges expected;
    for (const BlockCells& b : blocks) {
      block::forEachSetBit(b.cells, [&](int cell) {
        const VoxelKey k = block::keyOf(b.key, cell);
        const float v = wanted.at(k.packed());
        if (std::isnan(v)) {
          if (plain.logOdds(k).has_value()) {
            plain.erase(k);
            expected.push_back({k, 0.0F, false});
          }
        } else if (plain.logOdds(k) != v) {
          plain.setLogOdds(k, v);
          expected.push_back({k, v, true});
        }
      });
    }
    const auto values = [&](std::uint64_t key, const block::BlockMask& cells,
                            std::array<float, block::kVoxels>& out) {
      block::forEachSetBit(
          cells, [&](int cell) { out[cell] = wanted.at(block::keyOf(key, cell).packed()); });
    };
    for (std::size_t t = 0; t < maps.size(); ++t) {
      SCOPED_TRACE("lanes " + std::to_string(kLanes[t / 2]) + ", threads " +
                   std::to_string(t % 2 + 1));
      tbb::task_arena arena(static_cast<int>(t % 2) + 1);
      CellChanges changes;
      std::size_t updated = 0;
      arena.execute(
          [&] { updated = maps[t]->assignBlocks(blocks, values, &changes).updated_cells; });
      EXPECT_EQ(updated, wanted.size());
      ASSERT_EQ(changes.size(), expected.size()) << "round " << round;
      for (std::size_t i = 0; i < changes.size(); ++i) {
        EXPECT_EQ(changes[i].key, expected[i].key);
        EXPECT_EQ(changes[i].log_odds, expected[i].log_odds);
        EXPECT_EQ(changes[i].known, expected[i].known);
      }
      EXPECT_EQ(diffMaps(*maps[t], plain).differing(), 0U);
      EXPECT_EQ(maps[t]->knownCells(), plain.knownCells());
      const auto published = maps[t]->publishVersion();
      if (round == 3) {
        EXPECT_TRUE(published.written_blocks.empty());
      }
    }
    if (round == 1) {
      EXPECT_GT(std::count_if(expected.begin(), expected.end(),
                              [](const CellChange& c) { return !c.known; }),
                5);
    }
    if (round == 3) {
      EXPECT_TRUE(expected.empty());
    }
  }
  for (const auto& m : maps) expectFullyFreeMasksMatchValues(*m);
}

TEST(GridMap, QueriesByKeyAndPointAgreeAndUnknownIsEmpty) {
  GridMap sut(0.1, SensorModel{});
  EXPECT_FALSE(sut.logOddsAt(Point3f(1, 2, 3)).has_value());
  const VoxelKey k = *sut.grid().pointToKey(Point3f(1.05F, 2.05F, 3.05F));
  sut.setLogOdds(k, 1.5F);
  EXPECT_EQ(sut.logOdds(k), 1.5F);
  EXPECT_EQ(sut.logOddsAt(Point3f(1.01F, 2.09F, 3.02F)), 1.5F);
  EXPECT_EQ(sut.knownCells(), 1U);
  EXPECT_GT(sut.memoryBytes(), sizeof(VoxelBlock));
  sut.clear();
  EXPECT_EQ(sut.knownCells(), 0U);
  EXPECT_FALSE(sut.logOdds(k).has_value());
}

TEST(OctreeMap, ExpandsPrunedLeavesWhenIterating) {
  OctreeMap sut(0.1, SensorModel{});
  // Eight siblings with one value get pruned into their parent by OctoMap.
  for (std::uint16_t dz = 0; dz < 2; ++dz) {
    for (std::uint16_t dy = 0; dy < 2; ++dy) {
      for (std::uint16_t dx = 0; dx < 2; ++dx) {
        sut.setLogOdds(
            VoxelKey{static_cast<std::uint16_t>(32768 + dx), static_cast<std::uint16_t>(32768 + dy),
                     static_cast<std::uint16_t>(32768 + dz)},
            -2.0F);
      }
    }
  }
  const_cast<octomap::OcTree&>(sut.tree()).prune();
  EXPECT_EQ(sut.tree().getNumLeafNodes(), 1U);
  std::size_t n = 0;
  sut.forEachKnown([&](const VoxelKey& k, float v) {
    ++n;
    EXPECT_EQ(v, -2.0F);
    EXPECT_LE(k.x, 32769);
    EXPECT_GE(k.x, 32768);
  });
  EXPECT_EQ(n, 8U);
  EXPECT_EQ(sut.knownCells(), 8U);
}

TEST(MapFactory, RejectsBadBackendsAndResolutions) {
  EXPECT_FALSE(parseBackend("voxels").has_value());
  EXPECT_EQ(*parseBackend("octree"), Backend::kOctree);
  EXPECT_FALSE(makeMap(Backend::kGrid, 0.0).has_value());
  EXPECT_FALSE(makeMap(Backend::kGrid, std::nan("")).has_value());
  EXPECT_FALSE(makeMap(Backend::kGrid, 1e9).has_value());
  EXPECT_FALSE(makeMap(Backend::kGrid, 0.1, SensorModel({0.3, 0.4, 0.1, 0.9})).has_value());
  EXPECT_TRUE(makeMap(Backend::kOctree, 0.1).has_value());
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

TEST(OccupancyMaps, ReportTheSameChangesAndClearTheSameBox) {
  std::mt19937 rng_a(21), rng_b(21);
  GridMap grid(0.1, SensorModel{});
  OctreeMap octree(0.1, SensorModel{});
  for (int scan = 0; scan < 4; ++scan) {
    CellChanges ca, cb;
    const ApplyStats sa = grid.apply(randomUpdate(rng_a, 0.3), &ca);
    const ApplyStats sb = octree.apply(randomUpdate(rng_b, 0.3), &cb);
    ASSERT_EQ(ca.size(), sa.changed_cells);
    ASSERT_EQ(cb.size(), sb.changed_cells);
    auto sorted = [](CellChanges c) {
      std::sort(c.begin(), c.end(), [](const CellChange& x, const CellChange& y) {
        return x.key.packed() < y.key.packed();
      });
      return c;
    };
    const CellChanges a = sorted(ca), b = sorted(cb);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].key, b[i].key);
      EXPECT_EQ(a[i].log_odds, b[i].log_odds);
      EXPECT_EQ(grid.logOdds(a[i].key), a[i].log_odds);  // changes carry the new value
    }
  }
  const VoxelKey lo{32720, 32720, 32690}, hi{32760, 32800, 32700};
  CellChanges ea, eb;
  const std::size_t na = grid.clearBox(lo, hi, &ea);
  const std::size_t nb = octree.clearBox(lo, hi, &eb);
  EXPECT_GT(na, 1000U);
  EXPECT_EQ(na, nb);
  EXPECT_EQ(ea.size(), na);
  for (const CellChange& c : ea) {
    EXPECT_FALSE(c.known);
    EXPECT_FALSE(grid.logOdds(c.key).has_value());
  }
  EXPECT_EQ(diffMaps(grid, octree).differing(), 0U);
  EXPECT_EQ(grid.knownCells(), octree.knownCells());
}

}  // namespace
}  // namespace densemap
