#include "densemap/traversal/scan_update.hpp"

#include "densemap/traversal/dense_marks.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>
#include <span>
#include <tuple>

#include "densemap/parallel/tbb_runner.hpp"

namespace densemap {
namespace {

TEST(ScanUpdate, OccupiedWinsOverFreeAndEachCellIsListedOnce) {
  ScanUpdate sut;
  const VoxelKey a{100, 200, 300}, b{101, 200, 300}, c{7, 8, 9};
  sut.markFree(a);
  sut.markFree(a);
  sut.markFree(b);
  sut.markOccupied(b);
  sut.markOccupied(c);
  std::map<std::uint64_t, bool> seen;
  sut.forEachCell([&](const VoxelKey& k, const CellHits& h) {
    EXPECT_EQ(h.free + h.occupied, 1U) << "set rule: one hit or one miss";
    EXPECT_TRUE(seen.emplace(k.packed(), h.occupied > 0).second) << "listed twice";
  });
  EXPECT_EQ(seen.size(), 3U);
  EXPECT_FALSE(seen.at(a.packed()));
  EXPECT_TRUE(seen.at(b.packed()));
  EXPECT_TRUE(seen.at(c.packed()));
  EXPECT_EQ(sut.freeCount(), 1U);
  EXPECT_EQ(sut.occupiedCount(), 2U);
}

TEST(ScanUpdate, PerRayCountsEveryRayWithItsWeight) {
  ScanUpdate sut(UpdateRule::kPerRay);
  const VoxelKey a{100, 200, 300}, b{101, 200, 300};
  sut.markFree(a);
  sut.markFree(a, 4);
  sut.markFree(b, 2);
  sut.markOccupied(b, 3);
  std::map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> seen;
  sut.forEachCell([&](const VoxelKey& k, const CellHits& h) {
    seen[k.packed()] = {h.free, h.occupied};
  });
  EXPECT_EQ(seen.at(a.packed()), std::make_pair(5U, 0U));
  EXPECT_EQ(seen.at(b.packed()), std::make_pair(2U, 3U));  // both counts kept
}

// The update keeps its blocks' room from scan to scan (clearing and appending walk nothing):
// a block made in the room of an earlier one carries none of its marks or counts, and a
// moved-from update is empty.
TEST(ScanUpdate, AReusedUpdateCarriesNothingOfEarlierScans) {
  ScanUpdate sut;
  for (std::uint16_t i = 0; i < 50; ++i) {
    for (std::uint16_t c = 0; c < 8; ++c) {
      sut.markFree({static_cast<std::uint16_t>(8 * i + c), c, 0});
      sut.markOccupied({static_cast<std::uint16_t>(8 * i + c), 7, 7});
    }
  }
  ASSERT_EQ(sut.blocks().size(), 50U);
  const VoxelKey a{4000, 8, 8}, b{4008, 8, 8}, c{4016, 9, 9};
  using Hits = std::map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>>;
  const auto cells = [](const ScanUpdate& u) {
    Hits out;
    u.forEachCell([&](const VoxelKey& k, const CellHits& h) {
      out[k.packed()] = {h.free, h.occupied};
    });
    return out;
  };
  sut.reset(UpdateRule::kSet);
  EXPECT_TRUE(sut.empty());
  sut.markFree(a);
  sut.markOccupied(b);
  EXPECT_EQ(cells(sut), (Hits{{a.packed(), {1, 0}}, {b.packed(), {0, 1}}}));
  EXPECT_EQ(sut.freeCount(), 1U);
  EXPECT_EQ(sut.occupiedCount(), 1U);
  // Counts under kPerRay start at zero in a reused block, and are gone under kSet again.
  sut.reset(UpdateRule::kPerRay);
  sut.markFree(a, 3);
  sut.markFree(c, 2);
  sut.markOccupied(c);
  EXPECT_EQ(cells(sut), (Hits{{a.packed(), {3, 0}}, {c.packed(), {2, 1}}}));
  sut.reset(UpdateRule::kSet);  // the same blocks in the same places, as counts would add up
  sut.markFree(a);
  sut.markFree(c);
  EXPECT_EQ(cells(sut), (Hits{{a.packed(), {1, 0}}, {c.packed(), {1, 0}}}));
  ScanUpdate moved = std::move(sut);
  EXPECT_EQ(cells(moved), (Hits{{a.packed(), {1, 0}}, {c.packed(), {1, 0}}}));
  EXPECT_TRUE(sut.empty());  // NOLINT(bugprone-use-after-move): moved-from is specified empty
  EXPECT_EQ(sut.blocks().size(), 0U);
  sut.markOccupied(b);
  EXPECT_EQ(cells(sut), (Hits{{b.packed(), {0, 1}}}));
}

class ScanUpdateMerge : public ::testing::TestWithParam<UpdateRule> {};

TEST_P(ScanUpdateMerge, IsOrderIndependent) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(30000, 30040);
  std::bernoulli_distribution occ(0.2);
  std::uniform_int_distribution<std::uint32_t> weight(1, 9);
  const UpdateRule rule = GetParam();
  ScanUpdate parts[3] = {ScanUpdate(rule), ScanUpdate(rule), ScanUpdate(rule)};
  ScanUpdate all(rule);
  for (int i = 0; i < 5000; ++i) {
    const VoxelKey k{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                     static_cast<std::uint16_t>(coord(rng))};
    const bool o = occ(rng);
    const std::uint32_t w = weight(rng);
    ScanUpdate& part = parts[i % 3];
    o ? part.markOccupied(k, w) : part.markFree(k, w);
    o ? all.markOccupied(k, w) : all.markFree(k, w);
  }
  ScanUpdate forward(rule), backward(rule);
  for (int i = 0; i < 3; ++i) forward.merge(parts[i]);
  for (int i = 2; i >= 0; --i) backward.merge(parts[i]);
  auto collect = [](const ScanUpdate& u) {
    std::map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> m;
    u.forEachCell([&](const VoxelKey& k, const CellHits& h) {
      m[k.packed()] = {h.free, h.occupied};
    });
    return m;
  };
  EXPECT_EQ(collect(forward), collect(all));
  EXPECT_EQ(collect(backward), collect(all));
  EXPECT_GT(collect(all).size(), 4000U);
}

INSTANTIATE_TEST_SUITE_P(Rules, ScanUpdateMerge,
                         ::testing::Values(UpdateRule::kSet, UpdateRule::kPerRay),
                         [](const auto& rule) { return std::string(ruleName(rule.param)); });

TEST(BlockLayout, KeyOfInvertsBlockAndIndex) {
  for (const VoxelKey k :
       {VoxelKey{0, 0, 0}, VoxelKey{65535, 65535, 65535}, VoxelKey{32768, 7, 9}}) {
    EXPECT_EQ(block::keyOf(block::blockOf(k), block::indexOf(k)), k);
  }
}

}  // namespace
}  // namespace densemap

namespace densemap {
namespace {

/// Cells of an update as (packed key -> occupied?), for comparing two updates.
std::map<std::uint64_t, bool> cellsOf(const ScanUpdate& u) {
  std::map<std::uint64_t, bool> cells;
  u.forEachCell(
      [&](const VoxelKey& k, const CellHits& h) { cells.emplace(k.packed(), h.occupied > 0); });
  return cells;
}

TEST(DenseMarks, GivesTheSameUpdateAsTheHashInsideAndOutsideItsBox) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(32700, 32800);
  DenseMarks dense;
  for (int round = 0; round < 3; ++round) {  // reused: flushing must clear it
    ASSERT_TRUE(dense.reset({32720, 32730, 32740}, {32790, 32780, 32770}, 1000));
    ScanUpdate plain, sut;
    for (int i = 0; i < 5000; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng))};
      if (i % 7 == 0) {
        plain.markOccupied(k);
        dense.markOccupied(k, sut);
      } else {
        plain.markFree(k);
        dense.markFree(k, sut);  // many keys fall outside the box
      }
    }
    dense.flushInto(sut);
    EXPECT_EQ(cellsOf(sut), cellsOf(plain)) << "round " << round;
    EXPECT_EQ(sut.freeCount(), plain.freeCount());
    EXPECT_EQ(sut.occupiedCount(), plain.occupiedCount());
    EXPECT_GT(plain.occupiedCount(), 500U);
  }
}

// markOccupiedLanes marks the lanes' keys in the box as markOccupied does and names the others.
TEST(DenseMarks, OccupiedLanesAreMarkOccupiedKeyByKey) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> coord(32700, 32800);
  std::uniform_int_distribution<unsigned> lanes(0, 255);
  DenseMarks dense, one;
  for (int round = 0; round < 3; ++round) {
    ASSERT_TRUE(dense.reset({32720, 32730, 32740}, {32790, 32780, 32770}, 1000));
    ASSERT_TRUE(one.reset({32720, 32730, 32740}, {32790, 32780, 32770}, 1000));
    ScanUpdate plain, sut;
    std::size_t outside = 0, inside = 0;
    for (int i = 0; i < 2000; ++i) {
      VoxelKey keys[8];
      for (VoxelKey& k : keys) {
        k = {static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
             static_cast<std::uint16_t>(coord(rng))};
      }
      const unsigned which = lanes(rng);
      const unsigned out = dense.markOccupiedLanes(keys, which);
      for (int l = 0; l < 8; ++l) {
        if ((which >> l & 1U) == 0) continue;
        one.markOccupied(keys[l], plain);
        ScanUpdate alone;
        one.markOccupied(keys[l], alone);
        EXPECT_EQ((out >> l & 1U) != 0, !alone.empty()) << "lane " << l;  // outside the box
        if ((out >> l & 1U) != 0) {
          sut.markOccupied(keys[l]);
          ++outside;
        } else {
          ++inside;
        }
      }
      EXPECT_EQ(out & ~which, 0U);
    }
    dense.flushInto(sut);
    one.flushInto(plain);
    EXPECT_EQ(cellsOf(sut), cellsOf(plain)) << "round " << round;
    EXPECT_GT(outside, 500U);
    EXPECT_GT(inside, 500U);
  }
}

TEST(DenseMarks, AResetDropsMarksAScanLeftUnflushed) {
  DenseMarks dense;
  ASSERT_TRUE(dense.reset({32720, 32730, 32740}, {32790, 32780, 32770}, 1000));
  ScanUpdate outside;
  dense.markFree({32750, 32750, 32750}, outside);
  dense.markOccupied({32751, 32750, 32750}, outside);
  // The scan threw before its flush: the next scan starts empty.
  ASSERT_TRUE(dense.reset({32720, 32730, 32740}, {32790, 32780, 32770}, 1000));
  dense.markFree({32760, 32760, 32760}, outside);
  ScanUpdate sut;
  dense.flushInto(sut);
  EXPECT_EQ(sut.freeCount(), 1U);
  EXPECT_EQ(sut.occupiedCount(), 0U);
  EXPECT_TRUE(outside.empty());
}

// Runs the chunks last to first, one at a time: an order no serial flush takes.
class BackwardRunner final : public ChunkRunner {
 public:
  void run(std::size_t n, std::size_t, const Body& body) const override {
    for (std::size_t c = n; c-- > 0;) body(c, c + 1);
  }
};

/// The runners a flush is checked under: in order, in parallel, and in reverse order.
std::vector<const ChunkRunner*> flushRunners() {
  static const BackwardRunner backward;
  return {&serialRunner(), &tbbRunner(), &backward};
}

/// Whether `k` is in the dense box from `lo` to `hi` (the box is whole blocks).
bool inBlockBox(const VoxelKey& k, const VoxelKey& lo, const VoxelKey& hi) {
  bool inside = true;
  for (int axis = 0; axis < 3; ++axis) {
    inside = inside && (k[axis] >> 3) >= (lo[axis] >> 3) && (k[axis] >> 3) <= (hi[axis] >> 3);
  }
  return inside;
}

/// Sorts block keys in the box's block order: x fastest, then y, then z.
void sortInBoxOrder(std::vector<std::uint64_t>::iterator first,
                    std::vector<std::uint64_t>::iterator last) {
  const auto zyx = [](std::uint64_t key) {
    const VoxelKey corner = block::keyOf(key, 0);
    return std::tuple(corner.z, corner.y, corner.x);
  };
  std::sort(first, last, [&](std::uint64_t p, std::uint64_t q) { return zyx(p) < zyx(q); });
}

/// Marks `k` (occupied or free) in the plain update and in a worker's dense marks alike.
void markBoth(const VoxelKey& k, bool occupied, ScanUpdate& plain, DenseMarks& into,
              ScanUpdate& outside) {
  if (occupied) {
    plain.markOccupied(k);
    into.markOccupied(k, outside);
  } else {
    plain.markFree(k);
    into.markFree(k, outside);
  }
}

/// After a flush: every worker's marks are cleared, and the update's index finds the blocks
/// the flush appended (marking one again adds no block).
void expectFlushedAndIndexed(std::span<DenseMarks* const> workers, ScanUpdate& sut,
                             const std::vector<std::uint64_t>& got_order) {
  for (DenseMarks* w : workers) {
    ScanUpdate left;
    w->flushInto(left);
    EXPECT_TRUE(left.empty());
  }
  ASSERT_FALSE(got_order.empty());
  const std::size_t blocks = sut.blocks().size();
  sut.markFree(block::keyOf(got_order[got_order.size() / 2], 0));
  EXPECT_EQ(sut.blocks().size(), blocks);
}

// Several workers' marks flushed together (flushAllInto: the same box ORed in by block index in
// chunks, another box flushed after) give the update of all the marks, the box's blocks in
// block order and then the other box's, whichever order the chunks run in; every worker's
// marks are cleared.
TEST(DenseMarks, FlushingAllWorkersMarksGivesTheUpdateOfAll) {
  for (const ChunkRunner* runner : flushRunners()) {
    std::mt19937 rng(8);
    std::uniform_int_distribution<int> coord(32600, 32800);
    const VoxelKey lo{32600, 32610, 32620}, hi{32790, 32780, 32770};
    DenseMarks a, b, c, other_box;
    ASSERT_TRUE(a.reset(lo, hi, 100000));
    ASSERT_TRUE(b.reset(lo, hi, 100000));
    ASSERT_TRUE(c.reset(lo, hi, 100000));
    ASSERT_TRUE(other_box.reset(lo, {32800, 32780, 32770}, 100000));  // one block wider
    ScanUpdate plain, outside;
    // The serial order: a's blocks as first marked, then each other's new ones (as a's list
    // gains them), then the other box's.
    std::vector<std::uint64_t> order;
    std::set<std::uint64_t> listed;
    std::vector<std::uint64_t> order_b, order_c, order_other;
    DenseMarks* workers[4] = {&a, &b, &c, &other_box};
    std::vector<std::uint64_t>* orders[4] = {&order, &order_b, &order_c, &order_other};
    std::set<std::uint64_t> seen[4];
    for (int i = 0; i < 60000; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng))};
      const int w = i % 7 == 0 ? 3 : i % 3;
      DenseMarks& into = *workers[w];
      markBoth(k, i % 5 == 0, plain, into, outside);
      const VoxelKey& top = w == 3 ? VoxelKey{32800, 32780, 32770} : hi;
      if (inBlockBox(k, lo, top) && seen[w].insert(block::blockOf(k)).second) {
        orders[w]->push_back(block::blockOf(k));
      }
    }
    for (const auto* extra : {&order_b, &order_c}) {
      for (const std::uint64_t key : *extra) order.push_back(key);
    }
    std::vector<std::uint64_t> expected_order;
    for (const std::uint64_t key : order) {
      if (listed.insert(key).second) expected_order.push_back(key);
    }
    sortInBoxOrder(expected_order.begin(), expected_order.end());
    for (const std::uint64_t key : order_other) {  // the other box's, after, as first marked
      if (listed.insert(key).second) expected_order.push_back(key);
    }
    ScanUpdate sut;
    DenseMarks* others[3] = {&other_box, &b, &c};
    a.flushAllInto(others, sut, *runner);
    std::vector<std::uint64_t> got_order;
    for (const auto& [key, block] : sut.blocks()) got_order.push_back(key);
    EXPECT_EQ(got_order, expected_order);
    EXPECT_GT(got_order.size(), 2000U);  // many chunks
    sut.merge(outside);
    EXPECT_EQ(cellsOf(sut), cellsOf(plain));
    expectFlushedAndIndexed(workers, sut, got_order);
  }
}

// Blocks a walk entered and left without a mark (a culled walk may stop there) are listed but
// hold nothing: the flush leaves them out, the blocks after them in the box's order moved down
// over the gaps (flushAllInto writes each chunk of the list from its own room's start).
TEST(DenseMarks, FlushingLeavesOutBlocksEnteredWithoutMarks) {
  for (const ChunkRunner* runner : flushRunners()) {
    std::mt19937 rng(11);
    std::uniform_int_distribution<int> coord(32600, 32800);
    const VoxelKey lo{32600, 32610, 32620}, hi{32790, 32780, 32770};
    DenseMarks a, b;
    ASSERT_TRUE(a.reset(lo, hi, 100000));
    ASSERT_TRUE(b.reset(lo, hi, 100000));
    ScanUpdate plain, outside;
    std::set<std::uint64_t> marked, entered_only;
    for (int i = 0; i < 40000; ++i) {
      const VoxelKey k{static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng)),
                       static_cast<std::uint16_t>(coord(rng))};
      DenseMarks& into = i % 2 == 0 ? a : b;
      const bool inside = inBlockBox(k, lo, hi);
      if (i % 3 == 0 && inside) {  // entered, not marked
        DenseMarks::StepMarker walk(into, outside);
        const int delta[3] = {1, 0, 0};
        walk.begin(k, delta);
        walk.finish();
        entered_only.insert(block::blockOf(k));
        continue;
      }
      markBoth(k, i % 5 == 0, plain, into, outside);
      if (inside) marked.insert(block::blockOf(k));
    }
    std::size_t empty = 0;
    for (const std::uint64_t key : entered_only) empty += marked.count(key) == 0 ? 1 : 0;
    EXPECT_GT(empty, 1000U);  // gaps in most chunks
    std::vector<std::uint64_t> expected_order(marked.begin(), marked.end());
    sortInBoxOrder(expected_order.begin(), expected_order.end());
    ScanUpdate sut;
    DenseMarks* others[1] = {&b};
    a.flushAllInto(others, sut, *runner);
    std::vector<std::uint64_t> got_order;
    for (const auto& [key, block] : sut.blocks()) {
      got_order.push_back(key);
      EXPECT_TRUE(block::anyBit(block.free) || block::anyBit(block.occupied));
    }
    EXPECT_EQ(got_order, expected_order);
    sut.merge(outside);
    EXPECT_EQ(cellsOf(sut), cellsOf(plain));
    DenseMarks* const workers[2] = {&a, &b};
    expectFlushedAndIndexed(workers, sut, got_order);
  }
}

// Truncating below the blocks the key index holds: a dropped block marked again is a new
// block, and the kept ones are still found (no block added for them).
TEST(ScanUpdate, TruncatingDropsBlocksFromTheIndexToo) {
  ScanUpdate sut;
  std::vector<VoxelKey> keys;
  for (std::uint16_t i = 0; i < 40; ++i) keys.push_back({static_cast<std::uint16_t>(8 * i), 0, 0});
  for (const VoxelKey& k : keys) sut.markFree(k);  // one block each, all indexed
  ASSERT_EQ(sut.blocks().size(), keys.size());
  sut.truncateBlocks(10);
  ASSERT_EQ(sut.blocks().size(), 10U);
  for (std::size_t i = 0; i < 10; ++i) sut.markOccupied(keys[i]);
  EXPECT_EQ(sut.blocks().size(), 10U);
  sut.markFree(keys[25]);
  ASSERT_EQ(sut.blocks().size(), 11U);
  EXPECT_EQ(sut.blocks().back().first, block::blockOf(keys[25]));
  EXPECT_EQ(sut.occupiedCount(), 10U);
}

TEST(DenseMarks, RefusesABoxOverItsBlockLimit) {
  DenseMarks dense;
  EXPECT_FALSE(dense.reset({0, 0, 0}, {799, 799, 799}, 100 * 100 * 99));
  EXPECT_TRUE(dense.reset({0, 0, 0}, {799, 799, 799}, 100 * 100 * 100));
  // A refused box covers nothing: every mark goes to the fallback update.
  ASSERT_FALSE(dense.reset({0, 0, 0}, {65535, 65535, 65535}, 1000));
  ScanUpdate outside;
  dense.markFree({5, 5, 5}, outside);
  EXPECT_EQ(outside.freeCount(), 1U);
}

}  // namespace
}  // namespace densemap
