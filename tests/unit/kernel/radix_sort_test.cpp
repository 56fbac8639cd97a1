#include "radix_sort.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <optional>
#include <random>
#include <utility>
#include <vector>

namespace densemap::kernel {
namespace {

using Pairs = std::vector<std::pair<std::uint64_t, std::uint32_t>>;

/// The items' order by a stable sort of their packed voxel keys (none last), and the groups of
/// equal voxels as runs of item indices.
std::vector<std::vector<std::uint32_t>> groupsOf(const Pairs& pairs) {
  std::vector<std::vector<std::uint32_t>> groups;
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    if (p == 0 || pairs[p].first != pairs[p - 1].first) groups.emplace_back();
    groups.back().push_back(pairs[p].second);
  }
  return groups;
}

/// sortByVoxel groups and orders the items as a stable sort by packed key does (none last, in
/// one group), whether the keys are ranked in the window or, where one escapes it, packed.
void expectPackedOrder(const std::vector<std::optional<VoxelKey>>& keys,
                       const std::optional<KeyWindow>& window, bool ranked) {
  Pairs expected;
  const std::uint64_t none = std::uint64_t{1} << 48;
  for (std::uint32_t i = 0; i < keys.size(); ++i)
    expected.emplace_back(keys[i] ? keys[i]->packed() : none, i);
  std::stable_sort(expected.begin(), expected.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  Pairs pairs, scratch;
  std::vector<std::uint32_t> counts;
  const std::uint64_t got_none = sortByVoxel(
      keys.size(), [&](std::size_t i) { return keys[i]; }, window, pairs, scratch, counts);
  EXPECT_EQ(groupsOf(pairs), groupsOf(expected));
  EXPECT_EQ(got_none != none, ranked);
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    EXPECT_EQ(pairs[p].first == got_none, !keys[pairs[p].second].has_value());
  }
}

TEST(SortByVoxel, GivesThePackedKeysOrderInTheWindowAndOutOfIt) {
  const VoxelGrid grid(0.2);
  const Eigen::Vector3d origin(12.3, -40.1, 1.7);
  const double max_range = 30.0;
  const std::optional<KeyWindow> window = KeyWindow::around(grid, origin, max_range);
  ASSERT_TRUE(window.has_value());
  EXPECT_LT(window->bits(), 34);  // 3 passes of 11 bits, not 5
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> offset(-max_range, max_range);
  // Hits within max range (many a voxel: few distinct), a few with no voxel; 70,000 items
  // span several of the sort's chunks.
  std::vector<std::optional<VoxelKey>> keys;
  for (int i = 0; i < 70000; ++i) {
    Eigen::Vector3d p(origin.x() + offset(rng), origin.y() + offset(rng),
                      origin.z() + 0.1 * offset(rng));
    if (i % 3 == 0) p = origin + Eigen::Vector3d(0.05 * (i % 7), 0.0, 0.0);
    keys.push_back(i % 101 == 0 ? std::nullopt : grid.pointToKey(p.cast<float>()));
  }
  expectPackedOrder(keys, window, true);
  expectPackedOrder(keys, std::nullopt, false);
  // A voxel outside the window: packed keys for all, the same order.
  keys.push_back(grid.pointToKey(Eigen::Vector3f(12.3F + 31.0F, -40.1F, 1.7F)));
  expectPackedOrder(keys, window, false);
  expectPackedOrder({}, window, true);
}

TEST(KeyWindow, RanksTheWindowsKeysInPackedOrderAndNothingElse) {
  const VoxelGrid grid(0.1);
  const std::optional<KeyWindow> window = KeyWindow::around(grid, Eigen::Vector3d(0, 0, 0), 1.0);
  ASSERT_TRUE(window.has_value());
  const VoxelKey centre = *grid.pointToKey(Eigen::Vector3f(0, 0, 0));
  std::vector<std::pair<std::uint64_t, std::uint64_t>> packed_and_rank;
  for (int dz = -12; dz <= 12; dz += 3) {
    for (int dy = -12; dy <= 12; dy += 4) {
      for (int dx = -12; dx <= 12; ++dx) {
        const VoxelKey k{static_cast<std::uint16_t>(centre.x + dx),
                         static_cast<std::uint16_t>(centre.y + dy),
                         static_cast<std::uint16_t>(centre.z + dz)};
        const auto rank = window->rank(k);
        ASSERT_TRUE(rank.has_value()) << dx << " " << dy << " " << dz;
        EXPECT_LT(*rank, window->outside());
        packed_and_rank.emplace_back(k.packed(), *rank);
      }
    }
  }
  std::sort(packed_and_rank.begin(), packed_and_rank.end());
  for (std::size_t i = 1; i < packed_and_rank.size(); ++i) {
    EXPECT_LT(packed_and_rank[i - 1].second, packed_and_rank[i].second);
  }
  EXPECT_FALSE(window->rank(VoxelKey{static_cast<std::uint16_t>(centre.x + 40), centre.y, centre.z})
                   .has_value());
  EXPECT_FALSE(KeyWindow::around(grid, Eigen::Vector3d(0, 0, 0), -1.0).has_value());
}

TEST(BlockRanks, RankInBlockKeysOrderAndGiveTheirKeysBack) {
  BlockRanks ranks;
  ranks.low = {4000, 17, 8100};
  ranks.bits_x = 6;  // spans of up to 64, 32 and 16 blocks
  ranks.bits_y = 5;
  ranks.bits_z = 4;
  std::vector<std::pair<std::uint64_t, std::uint64_t>> key_and_rank;
  for (std::uint64_t bz = 8100; bz < 8116; bz += 3) {
    for (std::uint64_t by = 17; by < 49; by += 5) {
      for (std::uint64_t bx = 4000; bx < 4064; bx += 7) {
        const std::uint64_t key =
            block::blockOf(VoxelKey{static_cast<std::uint16_t>(bx << block::kShift),
                                    static_cast<std::uint16_t>(by << block::kShift),
                                    static_cast<std::uint16_t>(bz << block::kShift)});
        const std::uint64_t rank = ranks.rank(bx, by, bz);
        EXPECT_LT(rank, std::uint64_t{1} << ranks.bits());
        EXPECT_EQ(ranks.blockKey(rank), key);
        key_and_rank.emplace_back(key, rank);
      }
    }
  }
  std::sort(key_and_rank.begin(), key_and_rank.end());
  for (std::size_t i = 1; i < key_and_rank.size(); ++i) {
    EXPECT_LT(key_and_rank[i - 1].second, key_and_rank[i].second);
  }
}

}  // namespace
}  // namespace densemap::kernel
