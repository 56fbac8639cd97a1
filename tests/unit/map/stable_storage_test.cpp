#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <random>
#include <set>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/map/region_index.hpp"
#include "densemap/map/stable_vector.hpp"

namespace densemap {
namespace {

/// Counts its live instances, to see that the storage destroys what it built.
struct Counted {
  explicit Counted(int v) : value(v) { ++live; }
  Counted(const Counted&) = delete;
  Counted& operator=(const Counted&) = delete;
  ~Counted() { --live; }
  int value;
  static inline int live = 0;
};

TEST(StableVector, ElementsStayPutInOrderAndAreDestroyed) {
  {
    StableVector<Counted, 4, 64> sut;
    std::vector<const Counted*> where;
    for (int i = 0; i < 5000; ++i) where.push_back(&sut.emplace_back(i));
    EXPECT_EQ(sut.size(), 5000U);
    EXPECT_EQ(Counted::live, 5000);
    // No element moved, and iteration is insertion order.
    int i = 0;
    for (const Counted& c : sut) {
      ASSERT_EQ(&c, where[static_cast<std::size_t>(i)]);
      ASSERT_EQ(c.value, i);
      ++i;
    }
    EXPECT_EQ(i, 5000);
    // Chunks double from 4 to 64 elements: 4+8+16+32 = 60, then 78 chunks of 64 (5052 in all).
    EXPECT_EQ(sut.capacityBytes(), 5052 * sizeof(Counted));
    // A move hands the same elements over; the source is empty.
    StableVector<Counted, 4, 64> moved = std::move(sut);
    EXPECT_TRUE(sut.empty());  // NOLINT(bugprone-use-after-move): its state is specified
    EXPECT_EQ(sut.begin(), sut.end());
    EXPECT_EQ(&*moved.begin(), where.front());
    EXPECT_EQ(moved.size(), 5000U);
    EXPECT_EQ(Counted::live, 5000);
    moved.clear();
    EXPECT_EQ(Counted::live, 0);
    EXPECT_EQ(moved.capacityBytes(), 0U);
    moved.emplace_back(7);  // usable again
    EXPECT_EQ(moved.begin()->value, 7);
  }
  EXPECT_EQ(Counted::live, 0);
}

struct Entry {
  std::uint64_t key;
};

TEST(RegionIndex, FindsWhatAWalkOfAllEntriesFinds) {
  std::mt19937 rng(31);
  // Blocks around a corner of the key space and in clusters (many per region, > 63 so that
  // regions take several pages), in a random order.
  std::set<std::uint64_t> keys;
  std::uniform_int_distribution<std::uint32_t> near(0, 40), cluster(0, 9);
  for (int draw = 0; keys.size() < 6000; ++draw) {
    const bool dense = draw % 2 == 0;
    const std::uint32_t x = 4000 + (dense ? cluster(rng) : near(rng));
    const std::uint32_t y = 4000 + (dense ? cluster(rng) : near(rng));
    const std::uint32_t z = 4000 + near(rng) / 4;
    keys.insert(std::uint64_t{x} | (std::uint64_t{y} << 13) | (std::uint64_t{z} << 26));
  }
  std::vector<Entry> entries;
  for (const std::uint64_t k : keys) entries.push_back({k});
  std::shuffle(entries.begin(), entries.end(), rng);
  RegionIndex<Entry> sut;
  for (Entry& e : entries) sut.add(&e);

  // forEachRegion: every entry once, inside its region's box; a region's box holds 8^3 blocks.
  std::map<const Entry*, int> seen;
  std::size_t regions = 0;
  std::size_t most = 0;
  sut.forEachRegion([&](const block::BlockBox& box, auto&& for_each_entry) {
    ++regions;
    for (int a = 0; a < 3; ++a) EXPECT_EQ(box.max[a] - box.min[a], 7U);
    std::size_t n = 0;
    for_each_entry([&](Entry* e) {
      ++seen[e];
      ++n;
      EXPECT_TRUE(box.contains(e->key));
    });
    most = std::max(most, n);
  });
  EXPECT_EQ(seen.size(), entries.size());
  for (const auto& [e, times] : seen) EXPECT_EQ(times, 1);
  EXPECT_EQ(regions, sut.regions());
  EXPECT_GT(most, 62U);  // some region spans more than one page
  EXPECT_GE(sut.bytes(), entries.size() * sizeof(Entry*));

  // forEachIn: the entries in a box, for boxes smaller and larger than the map's regions.
  std::uniform_int_distribution<std::uint32_t> corner(3990, 4045), side(0, 30);
  for (int trial = 0; trial < 200; ++trial) {
    block::BlockBox box;
    for (int a = 0; a < 3; ++a) {
      box.min[a] = corner(rng);
      box.max[a] = box.min[a] + (trial == 0 ? 400 : side(rng));
    }
    std::vector<std::uint64_t> walked, indexed;
    for (const Entry& e : entries) {
      if (box.contains(e.key)) walked.push_back(e.key);
    }
    sut.forEachIn(box, [&](const Entry& e) { indexed.push_back(e.key); });
    std::sort(walked.begin(), walked.end());
    std::sort(indexed.begin(), indexed.end());
    ASSERT_EQ(indexed, walked) << "trial " << trial;
  }
  sut.clear();
  EXPECT_EQ(sut.regions(), 0U);
  std::size_t after = 0;
  sut.forEachRegion([&](const block::BlockBox&, auto&&) { ++after; });
  EXPECT_EQ(after, 0U);
}

}  // namespace
}  // namespace densemap
