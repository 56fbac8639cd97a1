// MapView over the versioned BlockStore: versions are immutable, readers see whole versions
// while the writer goes on, superseded blocks are freed once nobody reads them.
#include "densemap/pipeline/map_view.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <functional>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <unordered_map>

#include "densemap/pipeline/version_delta.hpp"

namespace densemap {
namespace {

using Cells = std::map<std::uint64_t, float>;  // packed key -> log-odds

Cells snapshotOf(const MapView& view) {
  Cells cells;
  view.forEachKnown([&](const VoxelKey& k, float v) { cells[k.packed()] = v; });
  return cells;
}

Cells snapshotOf(const GridMap& map) {
  Cells cells;
  map.forEachKnown([&](const VoxelKey& k, float v) { cells[k.packed()] = v; });
  return cells;
}

/// One version's worth of random writes and erasures in a 64^3 region (512 blocks).
void randomVersion(GridMap& map, std::mt19937& rng, int writes) {
  std::uniform_int_distribution<int> coord(32000, 32063);
  std::uniform_real_distribution<float> value(-2.0F, 3.5F);
  for (int i = 0; i < writes; ++i) {
    const VoxelKey k{static_cast<std::uint16_t>(coord(rng)), static_cast<std::uint16_t>(coord(rng)),
                     static_cast<std::uint16_t>(coord(rng))};
    if (rng() % 8 == 0) {
      map.erase(k);
    } else {
      map.setLogOdds(k, value(rng));
    }
  }
}

/// Order-independent checksum of a set of cells.
std::uint64_t checksum(
    const std::function<void(const std::function<void(const VoxelKey&, float)>&)>& for_each) {
  std::uint64_t sum = 0;
  for_each([&](const VoxelKey& k, float v) {
    std::uint32_t bits = 0;
    std::memcpy(&bits, &v, sizeof(bits));
    sum += (k.packed() * 0x9E3779B97F4A7C15ULL) ^ (std::uint64_t{bits} * 0xC2B2AE3D27D4EB4FULL);
  });
  return sum;
}

TEST(MapView, EveryHeldVersionKeepsExactlyTheCellsItWasPublishedWith) {
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(7);
  std::vector<std::pair<std::shared_ptr<const MapView>, Cells>> held;
  for (int v = 0; v < 60; ++v) {
    randomVersion(sut, rng, 400);
    auto view = MapView::publish(sut);
    EXPECT_EQ(view->version(), static_cast<std::uint64_t>(v));
    EXPECT_EQ(view->knownCells(), snapshotOf(sut).size());
    if (v % 7 == 0) held.emplace_back(view, snapshotOf(sut));
  }
  sut.clear();  // a versioned map erases by copy on write: held versions are untouched
  EXPECT_EQ(sut.knownCells(), 0U);
  for (const auto& [view, cells] : held) {
    EXPECT_EQ(snapshotOf(*view), cells) << "version " << view->version();
    for (const auto& [packed, value] : cells) {
      ASSERT_EQ(view->logOdds(VoxelKey::fromPacked(packed)), value);
    }
  }
}

TEST(MapView, SupersededBlocksAreFreedWhenTheLastReaderOfTheirVersionLetsGo) {
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(3);
  randomVersion(sut, rng, 3000);
  (void)MapView::publish(sut);
  const std::size_t blocks = sut.store()->entryCount();
  // No reader: each block has exactly one node, whatever the number of versions.
  for (int v = 0; v < 20; ++v) {
    randomVersion(sut, rng, 500);
    (void)MapView::publish(sut);
    EXPECT_EQ(sut.store()->liveNodes(), sut.store()->entryCount());
  }
  // A reader of an old version keeps the blocks written since, and only those.
  auto old = MapView::publish(sut);
  const Cells old_cells = snapshotOf(*old);
  for (int v = 0; v < 10; ++v) {
    randomVersion(sut, rng, 500);
    (void)MapView::publish(sut);
  }
  EXPECT_GT(sut.store()->liveNodes(), sut.store()->entryCount());
  EXPECT_LE(sut.store()->liveNodes(), sut.store()->entryCount() * 11);
  EXPECT_EQ(snapshotOf(*old), old_cells);
  old.reset();
  EXPECT_EQ(sut.store()->liveNodes(), sut.store()->entryCount());
  EXPECT_GE(sut.store()->entryCount(), blocks);
}

TEST(MapView, ReservedBlocksServeTheFirstVersionsWithoutGrowingThePool) {
  GridMap sut(0.1, SensorModel{});
  sut.reserveBlocks(4096);
  const std::size_t reserved = sut.memoryBytes();
  EXPECT_GE(reserved, 4096 * sizeof(BlockNode));
  EXPECT_EQ(sut.store()->liveNodes(), 0U);
  std::mt19937 rng(19);
  for (int v = 0; v < 10; ++v) {  // 512 blocks at most, copied on write while published
    randomVersion(sut, rng, 300);
    (void)MapView::publish(sut);
  }
  EXPECT_GT(sut.store()->liveNodes(), 0U);
  EXPECT_EQ(sut.memoryBytes() - sut.store()->entryCount() * sizeof(BlockEntry),
            reserved);  // the same slabs (only entries and table were added)
}

TEST(MapView, AnUnversionedMapWritesInPlace) {
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(5);
  for (int v = 0; v < 5; ++v) randomVersion(sut, rng, 2000);
  EXPECT_EQ(sut.store()->liveNodes(), sut.store()->entryCount());
  EXPECT_FALSE(sut.store()->versioned());
}

TEST(MapView, ConcurrentReadersAlwaysSeeWholeVersions) {
  GridMap map(0.1, SensorModel{});
  std::mutex sums_mutex;
  std::unordered_map<std::uint64_t, std::uint64_t> sums;  // version -> checksum
  std::atomic<std::shared_ptr<const MapView>> latest;
  auto publish = [&] {
    const std::uint64_t sum = checksum([&](const auto& f) { map.forEachKnown(f); });
    {
      std::lock_guard lock(sums_mutex);
      sums[map.store()->writingVersion()] = sum;
    }
    latest.store(MapView::publish(map));
  };
  publish();
  std::atomic<bool> done{false};
  std::atomic<std::size_t> checked{0}, wrong{0};
  std::vector<std::thread> readers;
  for (int r = 0; r < 3; ++r) {
    readers.emplace_back([&] {
      while (!done.load()) {
        const auto view = latest.load();
        const std::uint64_t sum = checksum([&](const auto& f) { view->forEachKnown(f); });
        std::lock_guard lock(sums_mutex);
        wrong += sums.at(view->version()) != sum;
        ++checked;
      }
    });
  }
  std::mt19937 rng(11);
  for (int v = 0; v < 300; ++v) {
    randomVersion(map, rng, 300);
    publish();
  }
  done = true;
  for (auto& t : readers) t.join();
  EXPECT_GT(checked.load(), 0U);
  EXPECT_EQ(wrong.load(), 0U);
  latest.store(nullptr);
  EXPECT_EQ(map.store()->liveNodes(), map.store()->entryCount());
}

TEST(MapView, DiffOfTwoVersionsOverTheirWrittenBlocksTurnsOneIntoTheOther) {
  GridMap map(0.1, SensorModel{});
  std::mt19937 rng(13);
  randomVersion(map, rng, 2000);
  auto base = MapView::publish(map);
  std::vector<std::uint64_t> written;
  for (int v = 0; v < 4; ++v) {
    randomVersion(map, rng, 300);
    auto published = map.publishVersion();
    written.insert(written.end(), published.written_blocks.begin(), published.written_blocks.end());
  }
  auto next = MapView::publish(map);
  GridMap rebuilt(0.1, SensorModel{});
  base->forEachKnown([&](const VoxelKey& k, float v) { rebuilt.setLogOdds(k, v); });
  rebuilt.applyChanges(diffVersions(*base, *next, written).changes());
  EXPECT_EQ(snapshotOf(rebuilt), snapshotOf(*next));
  EXPECT_NE(snapshotOf(*base), snapshotOf(*next));
}

TEST(MapView, TilesHoldEveryCellOnceAndTheirCellsAreTheMap) {
  GridMap map(0.1, SensorModel{});
  std::mt19937 rng(17);
  randomVersion(map, rng, 5000);
  auto view = MapView::publish(map);
  randomVersion(map, rng, 500);  // later versions do not leak into the tiles of `view`
  (void)MapView::publish(map);
  const auto tiles = tilesOf(*view);
  ASSERT_GT(tiles.size(), 1U);
  GridMap rebuilt(0.1, SensorModel{});
  std::size_t cells = 0;
  for (const auto& [tile, blocks] : tiles) {
    const VersionDelta t = cellsOf(*view, blocks);
    ASSERT_TRUE(t.wellFormed());
    for (const CellChange& c : t.changes()) EXPECT_EQ(tileOf(c.key), tile);
    rebuilt.applyChanges(t.changes());
    cells += t.size();
  }
  EXPECT_EQ(cells, view->knownCells());
  EXPECT_EQ(snapshotOf(rebuilt), snapshotOf(*view));
}

TEST(VersionDelta, MalformedLayoutsAreRecognised) {
  VersionDelta ok;
  ok.block_keys = {5};
  ok.block_ends = {2};
  ok.cells = {0, 511};
  ok.log_odds = {1.0F, -1.0F};
  EXPECT_TRUE(ok.wellFormed());
  auto bad = ok;
  bad.cells[1] = 512;  // past a block
  EXPECT_FALSE(bad.wellFormed());
  bad = ok;
  bad.block_ends = {3};  // past the cells
  EXPECT_FALSE(bad.wellFormed());
  bad = ok;
  bad.log_odds.pop_back();
  EXPECT_FALSE(bad.wellFormed());
  bad = ok;
  bad.block_keys.push_back(6);  // a block without an end
  EXPECT_FALSE(bad.wellFormed());
}

}  // namespace
}  // namespace densemap
