#include "densemap/map/scan_update.hpp"

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
  sut.forEachCell([&](const VoxelKey& k, bool occ) {
    EXPECT_TRUE(seen.emplace(k.packed(), occ).second) << "listed twice";
  });
  EXPECT_EQ(seen.size(), 3U);
  EXPECT_FALSE(seen.at(a.packed()));
  EXPECT_TRUE(seen.at(b.packed()));
  EXPECT_TRUE(seen.at(c.packed()));
  EXPECT_EQ(sut.freeCount(), 1U);
  EXPECT_EQ(sut.occupiedCount(), 2U);
}

TEST(ScanUpdate, MergeIsOrderIndependent) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> coord(30000, 30040);
  std::bernoulli_distribution occ(0.2);
  ScanUpdate parts[3];
  ScanUpdate all;
  for (int i = 0; i < 5000; ++i) {
    const VoxelKey k{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                     static_cast<std::uint16_t>(coord(rng))};
    const bool o = occ(rng);
    ScanUpdate& part = parts[i % 3];
    o ? part.markOccupied(k) : part.markFree(k);
    o ? all.markOccupied(k) : all.markFree(k);
  }
  ScanUpdate forward, backward;
  for (int i = 0; i < 3; ++i) forward.merge(parts[i]);
  for (int i = 2; i >= 0; --i) backward.merge(parts[i]);
  auto collect = [](const ScanUpdate& u) {
    std::map<std::uint64_t, bool> m;
    u.forEachCell([&](const VoxelKey& k, bool o) { m[k.packed()] = o; });
    return m;
  };
  EXPECT_EQ(collect(forward), collect(all));
  EXPECT_EQ(collect(backward), collect(all));
}

TEST(BlockLayout, KeyOfInvertsBlockAndIndex) {
  for (const VoxelKey k :
       {VoxelKey{0, 0, 0}, VoxelKey{65535, 65535, 65535}, VoxelKey{32768, 7, 9}}) {
    EXPECT_EQ(block::keyOf(block::blockOf(k), block::indexOf(k)), k);
  }
}

}  // namespace
}  // namespace densemap
