// MapView over the versioned BlockStore: versions are immutable, readers see whole versions
// while the writer goes on, superseded blocks are freed once nobody reads them.
#include "densemap/query/map_view.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <stdexcept>
#include <thread>
#include <unordered_map>

#include "densemap/query/version_delta.hpp"
#include "densemap/test_support/failing_allocations.hpp"

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
  EXPECT_EQ(sut.memoryBytes() - sut.store()->entryBytes() - sut.store()->indexBytes(),
            reserved);  // the same slabs (only entries, their index and table were added)
}

TEST(MapView, AnUnversionedMapWritesInPlace) {
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(5);
  for (int v = 0; v < 5; ++v) randomVersion(sut, rng, 2000);
  EXPECT_EQ(sut.store()->liveNodes(), sut.store()->entryCount());
  EXPECT_FALSE(sut.store()->versioned());
}

TEST(MapView, LiveVersionsWriteInPlaceAndListEveryBlockEachVersionWrote) {
  // Two maps take the same writes: one publishes versions (copy on write), one advances live
  // versions (in place). Each version: the same contents, the same version number, and the
  // live list of written blocks holds exactly the blocks whose contents changed (or a superset
  // of them that the versioned list holds too), each once.
  GridMap versioned(0.1, SensorModel{}), live(0.1, SensorModel{});
  versioned.startVersionsAt(5);
  live.startVersionsAt(5);
  live.startLiveVersions();
  // The empty first version, as the engine publishes at its start (a store lists the blocks a
  // version wrote from its first published version on).
  ASSERT_EQ(MapView::publish(versioned)->version(), MapView::advanceLive(live)->version());
  std::mt19937 rng_a(9), rng_b(9);
  std::map<std::uint64_t, VoxelBlock> before;
  for (int v = 0; v < 8; ++v) {
    randomVersion(versioned, rng_a, 300);
    randomVersion(live, rng_b, 300);
    std::vector<std::uint64_t> written_versioned, written_live;
    const auto a = MapView::publish(versioned, 0, &written_versioned);
    const auto b = MapView::advanceLive(live, 0, &written_live);
    ASSERT_EQ(a->version(), b->version());
    EXPECT_EQ(a->version(), 6U + static_cast<unsigned>(v));
    EXPECT_EQ(a->knownCells(), b->knownCells());
    EXPECT_EQ(checksum([&](const auto& f) { a->forEachKnown(f); }),
              checksum([&](const auto& f) { b->forEachKnown(f); }));
    std::sort(written_live.begin(), written_live.end());
    EXPECT_EQ(std::adjacent_find(written_live.begin(), written_live.end()), written_live.end())
        << "a block listed twice in version " << v;
    std::sort(written_versioned.begin(), written_versioned.end());
    written_versioned.erase(std::unique(written_versioned.begin(), written_versioned.end()),
                            written_versioned.end());
    EXPECT_EQ(written_live, written_versioned) << "version " << v;
    // Every block whose contents differ from the last version is listed.
    std::map<std::uint64_t, VoxelBlock> now;
    b->forEachBlock([&](std::uint64_t key, const VoxelBlock& block) { now[key] = block; });
    const auto differs = [](const VoxelBlock& x, const VoxelBlock& y) {
      return std::memcmp(&x, &y, sizeof(VoxelBlock)) != 0;
    };
    for (const auto& [key, block] : now) {
      const auto old = before.find(key);
      if (old == before.end() || differs(old->second, block)) {
        EXPECT_TRUE(std::binary_search(written_live.begin(), written_live.end(), key));
      }
    }
    for (const auto& [key, block] : before) {
      if (!now.contains(key)) {
        EXPECT_TRUE(std::binary_search(written_live.begin(), written_live.end(), key));
      }
    }
    before = std::move(now);
  }
  // In place: one node per block with contents, never a copy; still unversioned.
  EXPECT_FALSE(live.store()->versioned());
  std::size_t with_contents = 0;
  live.store()->forEachEntry(
      [&](const BlockEntry& e) { with_contents += BlockStore::latest(e) != nullptr; });
  EXPECT_EQ(live.store()->liveNodes(), with_contents);
  EXPECT_TRUE(versioned.store()->versioned());
}

/// Cells of `map` in a block-aligned window of `blocks`^3 blocks at block offset `at`, each with
/// a value from `rng`.
void fillWindow(GridMap& map, std::mt19937& rng, int at, int blocks, int cells_per_block) {
  std::uniform_int_distribution<int> cell(0, block::kEdge - 1);
  std::uniform_real_distribution<float> value(-2.0F, 3.5F);
  for (int bx = at; bx < at + blocks; ++bx) {
    for (int by = 0; by < blocks; ++by) {
      for (int bz = 0; bz < 2; ++bz) {
        for (int c = 0; c < cells_per_block; ++c) {
          map.setLogOdds({static_cast<std::uint16_t>(32000 + bx * block::kEdge + cell(rng)),
                          static_cast<std::uint16_t>(32000 + by * block::kEdge + cell(rng)),
                          static_cast<std::uint16_t>(32000 + bz * block::kEdge + cell(rng))},
                         value(rng));
        }
      }
    }
  }
}

TEST(MapView, DroppedBlocksLeaveNewVersionsAndStayInHeldOnesThroughCompaction) {
  // A window of blocks slides along x; blocks behind it are evicted. Views held for a while
  // must keep exactly their version's cells while tombstones retire and entries compact.
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(11);
  std::vector<std::pair<std::shared_ptr<const MapView>, Cells>> held;
  std::size_t evicted_blocks = 0, boxed_blocks = 0;
  for (int v = 0; v < 160; ++v) {
    fillWindow(sut, rng, v, 24, 3);
    if (v % 10 == 5) randomVersion(sut, rng, 200);  // cells that come back in old blocks
    const float x_min =
        static_cast<float>(sut.grid().keyToPoint({32000, 0, 0}).x() + (v - 4) * block::kEdge * 0.1);
    const std::size_t known_before = sut.knownCells();
    const EvictStats stats =
        sut.evictBlocks([&](const Point3f& centre) { return centre.x() >= x_min; });
    evicted_blocks += stats.blocks;
    EXPECT_EQ(sut.knownCells(), known_before - stats.cells);
    // The region index (forEachEntryIn) finds the entries a walk of all of them finds in a
    // box, through drops and compactions.
    block::BlockBox box;
    const auto corner = block::coordsOf(block::blockOf(VoxelKey{32000, 32000, 32000}));
    for (int a = 0; a < 3; ++a) {
      box.min[a] = corner[a] + static_cast<std::uint32_t>(a == 0 ? v : a == 1 ? v % 7 : 0);
      box.max[a] = box.min[a] + static_cast<std::uint32_t>(a == 2 ? v % 2 : 3 + v % 11);
    }
    std::vector<std::uint64_t> walked, indexed;
    sut.store()->forEachEntry([&](const BlockEntry& e) {
      if (box.contains(e.key) && BlockStore::latest(e) != nullptr) walked.push_back(e.key);
    });
    sut.store()->forEachEntryIn(box, [&](const BlockEntry& e) {
      if (BlockStore::latest(e) != nullptr) indexed.push_back(e.key);
    });
    std::sort(walked.begin(), walked.end());
    std::sort(indexed.begin(), indexed.end());
    EXPECT_EQ(indexed, walked) << "version " << v;
    boxed_blocks += indexed.size();
    auto view = MapView::publish(sut);
    const Cells now = snapshotOf(sut);
    EXPECT_EQ(view->knownCells(), now.size());
    if (v % 9 == 0) held.emplace_back(view, now);
    if (held.size() > 4) {  // let the oldest go: its nodes and tombstones can be freed
      EXPECT_EQ(snapshotOf(*held.front().first), held.front().second);
      held.erase(held.begin());
    }
  }
  for (const auto& [view, cells] : held) {
    EXPECT_EQ(snapshotOf(*view), cells) << "version " << view->version();
  }
  EXPECT_GT(evicted_blocks, 8000U);
  EXPECT_GT(boxed_blocks, 1000U);  // the boxes met the window
  EXPECT_GE(sut.store()->compactions(), 1U) << "thousands of dropped entries were compacted";
  held.clear();
  for (int v = 0; v < 3; ++v) (void)MapView::publish(sut);
  // No reader left: one node per block with contents, no more entries than ~2x those.
  std::size_t with_contents = 0;
  sut.store()->forEachEntry(
      [&](const BlockEntry& e) { with_contents += BlockStore::latest(e) != nullptr; });
  EXPECT_EQ(sut.store()->liveNodes(), with_contents);
  EXPECT_LE(sut.store()->entryCount(), 2 * with_contents + 4096);
}

// A dense map's evidence lives in its blocks' entries: a drop takes it, a
// compaction keeps it (with contents or without) and leaves out the entries that have neither.
TEST(BlockStore, EvidenceGoesWithDropsAndSurvivesCompaction) {
  BlockStore store;
  (void)store.publish();  // versioned from here
  for (std::uint64_t k = 0; k < 6000; ++k) store.writable(store.entry(k)).voxels.markKnown(0);
  const std::size_t without_evidence = store.memoryBytes();
  for (std::uint64_t k = 0; k < 10; ++k) store.evidence(store.entry(k)).alpha[3] = 1.0F;
  for (std::uint64_t k = 100000; k < 100100; ++k) {
    store.evidence(store.entry(k)).alpha[3] = static_cast<float>(k);
  }
  for (std::uint64_t k = 200000; k < 201000; ++k) {
    (void)store.evidence(store.entry(k));
    store.dropEvidence(*store.findEntry(k));  // neither contents nor evidence left
  }
  EXPECT_EQ(store.evidenceBlocks(), 110U);
  EXPECT_GE(store.memoryBytes(), without_evidence + 110 * sizeof(BlockEvidence));
  (void)store.publish();
  for (std::uint64_t k = 0; k < 6000; ++k) EXPECT_TRUE(store.drop(*store.findEntry(k)));
  EXPECT_EQ(store.evidenceBlocks(), 100U);
  for (int v = 0; v < 4; ++v) (void)store.publish();
  EXPECT_GE(store.compactions(), 1U);
  EXPECT_EQ(store.entryCount(), 100U);
  for (std::uint64_t k = 100000; k < 100100; ++k) {
    const BlockEntry* e = store.findEntry(k);
    ASSERT_NE(e, nullptr);
    ASSERT_NE(e->evidence, nullptr);
    EXPECT_EQ(e->evidence->alpha[3], static_cast<float>(k));
  }
  EXPECT_EQ(store.findEntry(5), nullptr);
  EXPECT_EQ(store.findEntry(200000), nullptr);
}

// Writes through WriteBatch (nodes taken from the pool a few at a time, the version's
// bookkeeping kept until the batch ends) leave the same versions as writable(): the new
// version's contents copied from the last and changed, the old version's unchanged while held,
// every written block listed once, and every node back in the pool once nobody reads it (the
// batches' unused nodes included).
TEST(BlockStore, WritesThroughBatchesKeepTheVersionsBookkeeping) {
  BlockStore store;
  (void)store.publish();  // versioned from here
  for (std::uint64_t k = 0; k < 1000; ++k) {
    store.writable(store.entry(k)).voxels.markKnown(1);
  }
  BlockStore::Published held = store.publish();
  std::vector<BlockEntry*> entries;
  for (std::uint64_t k = 0; k < 1100; ++k) entries.push_back(&store.entry(k));  // 100 new
  // Two tasks, each with its own batch, over distinct blocks (odd and even).
  std::vector<std::thread> tasks;
  for (std::size_t part = 0; part < 2; ++part) {
    tasks.emplace_back([&, part] {
      BlockStore::WriteBatch batch(store);
      for (std::size_t j = part; j < entries.size(); j += 2) {
        batch.writable(*entries[j]).voxels.markKnown(2);
        batch.writable(*entries[j]).voxels.markKnown(3);  // the same node again
      }
    });
  }
  for (std::thread& t : tasks) t.join();
  const BlockStore::Published next = store.publish();
  std::vector<std::uint64_t> written = next.written_blocks;
  std::sort(written.begin(), written.end());
  ASSERT_EQ(written.size(), 1100U);
  for (std::uint64_t k = 0; k < 1100; ++k) EXPECT_EQ(written[k], k);
  EXPECT_EQ(store.liveNodes(), 1000U + 1100U);  // the held version's, and the new ones
  for (std::uint64_t k = 0; k < 1100; ++k) {
    const BlockNode* now = store.find(k, next.version);
    ASSERT_NE(now, nullptr);
    EXPECT_EQ(now->voxels.isKnown(1), k < 1000);  // copied from the last version
    EXPECT_TRUE(now->voxels.isKnown(2) && now->voxels.isKnown(3));
    const BlockNode* then = store.find(k, held.version);
    if (k < 1000) {
      ASSERT_NE(then, nullptr);
      EXPECT_TRUE(then->voxels.isKnown(1));
      EXPECT_FALSE(then->voxels.isKnown(2));
    } else {
      EXPECT_EQ(then, nullptr);
    }
  }
  held = {};
  (void)store.publish();
  EXPECT_EQ(store.liveNodes(), store.entryCount());
}

// A task that throws while no allocation can succeed unwinds through its batch: the batch
// hands its bookkeeping to the version within the room its refills kept (an allocation in
// its destructor would end the process), and the version it wrote is whole.
TEST(BlockStore, ABatchUnwindsWithoutAllocatingWhenItsTaskThrows) {
  BlockStore store;
  (void)store.publish();  // versioned from here
  for (std::uint64_t k = 0; k < 1000; ++k) store.writable(store.entry(k)).voxels.markKnown(1);
  BlockStore::Published held = store.publish();
  std::vector<BlockEntry*> entries;
  for (std::uint64_t k = 0; k < 1000; ++k) entries.push_back(&store.entry(k));
  const std::runtime_error failure("the task failed");  // made before allocations fail
  std::optional<test::FailingAllocations> failing;      // outlives the batch
  std::uint64_t failed_allocations = 0;
  bool caught = false;
  try {
    BlockStore::WriteBatch batch(store);
    for (BlockEntry* e : entries) batch.writable(*e).voxels.markKnown(2);
    failing.emplace(1, ~std::uint64_t{0}, test::FailingAllocations::kEveryThread);
    throw failure;
  } catch (const std::runtime_error&) {
    caught = true;
  }
  if (failing) failed_allocations = failing->failed();
  failing.reset();
  EXPECT_TRUE(caught);
  EXPECT_EQ(failed_allocations, 0U);  // the unwinding asked for no memory
  const BlockStore::Published next = store.publish();
  std::vector<std::uint64_t> written = next.written_blocks;
  std::sort(written.begin(), written.end());
  ASSERT_EQ(written.size(), 1000U);
  for (std::uint64_t k = 0; k < 1000; ++k) {
    EXPECT_EQ(written[k], k);
    const BlockNode* now = store.find(k, next.version);
    ASSERT_NE(now, nullptr);
    EXPECT_TRUE(now->voxels.isKnown(1) && now->voxels.isKnown(2));
    EXPECT_FALSE(store.find(k, held.version)->voxels.isKnown(2));
  }
  held = {};
  (void)store.publish();
  EXPECT_EQ(store.liveNodes(), store.entryCount());  // superseded nodes recycled, none lost
}

TEST(MapView, AWindowedDriveKeepsMemoryFlat) {
  GridMap sut(0.1, SensorModel{});
  sut.reserveBlocks(2048);
  std::mt19937 rng(13);
  std::vector<std::size_t> bytes;
  std::shared_ptr<const MapView> reader;  // a reader that holds each version for a while
  for (int v = 0; v < 400; ++v) {
    fillWindow(sut, rng, v, 16, 2);
    const float x_min =
        static_cast<float>(sut.grid().keyToPoint({32000, 0, 0}).x() + (v - 2) * block::kEdge * 0.1);
    (void)sut.evictBlocks([&](const Point3f& c) { return c.x() >= x_min; });
    auto view = MapView::publish(sut);
    if (v % 5 == 0) reader = view;
    if (v >= 100) bytes.push_back(sut.memoryBytes());
  }
  const auto [lo, hi] = std::minmax_element(bytes.begin(), bytes.end());
  std::printf("windowed drive: map memory %zu .. %zu bytes over versions 100-399, %zu entries\n",
              *lo, *hi, sut.store()->entryCount());
  EXPECT_LE(static_cast<double>(*hi), 1.10 * static_cast<double>(*lo))
      << "memory " << *lo << " .. " << *hi << " bytes over 300 versions";
}

TEST(MapView, ClearingAVersionedMapReturnsItsMemory) {
  GridMap sut(0.1, SensorModel{});
  std::mt19937 rng(17);
  fillWindow(sut, rng, 0, 60, 4);  // 7200 blocks, about 16 MB
  auto view = MapView::publish(sut);
  const Cells cells = snapshotOf(*view);
  const std::size_t full = sut.memoryBytes();
  sut.clear();
  EXPECT_EQ(sut.knownCells(), 0U);
  (void)MapView::publish(sut);
  EXPECT_EQ(snapshotOf(*view), cells) << "a held version keeps its cells";
  view.reset();
  for (int v = 0; v < 3; ++v) (void)MapView::publish(sut);
  EXPECT_EQ(sut.store()->liveNodes(), 0U);
  EXPECT_LT(sut.memoryBytes(), full / 4) << full << " bytes before the reset";
  // clear-bbox: blocks wholly inside the box are dropped, the rest erased cell by cell.
  fillWindow(sut, rng, 0, 8, 4);
  (void)MapView::publish(sut);
  const std::size_t blocks = sut.store()->liveNodes();
  const VoxelKey lo{32000, 32000, 32000};
  const VoxelKey hi{32000 + 4 * block::kEdge - 1, 32000 + 8 * block::kEdge - 1,
                    32000 + 2 * block::kEdge - 3};  // z: the upper blocks only in part
  CellChanges changes;
  const std::size_t erased = sut.clearBox(lo, hi, &changes);
  EXPECT_EQ(changes.size(), erased);
  for (const CellChange& c : changes) EXPECT_FALSE(sut.logOdds(c.key));
  for (int v = 0; v < 3; ++v) (void)MapView::publish(sut);
  EXPECT_LT(sut.store()->liveNodes(), blocks - 4 * 8 + 1) << "the lower blocks were dropped";
}

/// Three reader threads check whole versions (by checksum) while `write(v)` changes `map` for
/// each of `versions` versions and publishes it. Returns how many reads were checked and how
/// many saw a mixed version.
std::pair<std::size_t, std::size_t> readWhileWriting(GridMap& map, int versions,
                                                     const std::function<void(int)>& write) {
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
  for (int v = 0; v < versions; ++v) {
    write(v);
    publish();
  }
  done = true;
  for (auto& t : readers) t.join();
  return {checked.load(), wrong.load()};
}

TEST(MapView, ConcurrentReadersAlwaysSeeWholeVersions) {
  GridMap map(0.1, SensorModel{});
  std::mt19937 rng(11);
  const auto [checked, wrong] =
      readWhileWriting(map, 300, [&](int) { randomVersion(map, rng, 300); });
  EXPECT_GT(checked, 0U);
  EXPECT_EQ(wrong, 0U);
  EXPECT_EQ(map.store()->liveNodes(), map.store()->entryCount());
}

TEST(MapView, ConcurrentReadersSeeWholeVersionsWhileBlocksAreEvictedAndEntriesCompacted) {
  GridMap map(0.1, SensorModel{});
  std::mt19937 rng(23);
  const auto [checked, wrong] = readWhileWriting(map, 400, [&](int v) {
    fillWindow(map, rng, v, 16, 2);
    const float x_min =
        static_cast<float>(map.grid().keyToPoint({32000, 0, 0}).x() + (v - 2) * block::kEdge * 0.1);
    (void)map.evictBlocks([&](const Point3f& c) { return c.x() >= x_min; });
  });
  EXPECT_GT(checked, 0U);
  EXPECT_EQ(wrong, 0U);
  EXPECT_GE(map.store()->compactions(), 1U);
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
