#include "densemap/map/scan_update.hpp"

#include "densemap/map/dense_marks.hpp"

#include <gtest/gtest.h>

#include <map>
#include <random>

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
  u.forEachCell([&](const VoxelKey& k, const CellHits& h) {
    cells.emplace(k.packed(), h.occupied > 0);
  });
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

TEST(DenseMarks, AbsorbingAnotherWorkersMarksGivesTheUpdateOfBoth) {
  std::mt19937 rng(8);
  std::uniform_int_distribution<int> coord(32700, 32800);
  const VoxelKey lo{32720, 32730, 32740}, hi{32790, 32780, 32770};
  DenseMarks a, b, other_box;
  ASSERT_TRUE(a.reset(lo, hi, 1000));
  ASSERT_TRUE(b.reset(lo, hi, 1000));
  ASSERT_TRUE(other_box.reset(lo, {32800, 32780, 32770}, 1000));  // one block wider
  ScanUpdate plain, outside;
  for (int i = 0; i < 6000; ++i) {
    const VoxelKey k{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                     static_cast<std::uint16_t>(coord(rng))};
    DenseMarks& into = i % 2 == 0 ? a : b;
    if (i % 5 == 0) {
      plain.markOccupied(k);
      into.markOccupied(k, outside);
    } else {
      plain.markFree(k);
      into.markFree(k, outside);
    }
  }
  EXPECT_FALSE(a.absorb(other_box));  // another box: refused
  ASSERT_TRUE(a.absorb(b));
  ScanUpdate sut;
  a.flushInto(sut);
  sut.merge(outside);
  EXPECT_EQ(cellsOf(sut), cellsOf(plain));
  ScanUpdate left;
  b.flushInto(left);  // absorbed: nothing left
  EXPECT_TRUE(left.empty());
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
