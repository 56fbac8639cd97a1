#include "densemap/map/grid_map.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <vector>

namespace densemap {

void GridMap::store(BlockNode& node, int index, float log_odds) const {
  node.voxels.log_odds[index] = log_odds;
  if (sensorModel().isFullyFree(log_odds)) {
    block::setBit(node.fully_free, index);
  } else {
    block::clearBit(node.fully_free, index);
  }
}

ApplyStats GridMap::apply(const ScanUpdate& update, CellChanges* changes) {
  struct Job {
    std::uint64_t block_key;
    BlockEntry* entry;
    const ScanUpdate::Block* cells;
  };
  std::vector<Job> jobs;
  jobs.reserve(update.blocks().size());
  for (const auto& [block_key, cells] : update.blocks()) {
    jobs.push_back({block_key, &store_->entry(block_key), &cells});
  }

  // Each job records its changes in its own slot; slots are concatenated in job order.
  std::vector<CellChanges> job_changes(changes != nullptr ? jobs.size() : 0);
  struct Counts {
    std::size_t updated = 0, changed = 0, newly_known = 0;
  };
  const SensorModel& model = sensorModel();
  const UpdateRule rule = update.rule();
  static const BlockNode kEmpty{};
  const Counts total = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, jobs.size(), 16), Counts{},
      [&](const tbb::blocked_range<std::size_t>& range, Counts c) {
        for (std::size_t j = range.begin(); j != range.end(); ++j) {
          // Read the latest contents; the first change takes the writable node (a copy when
          // a published version still reads the head).
          const BlockNode* head = BlockStore::latest(*jobs[j].entry);
          const BlockNode* read = head != nullptr ? head : &kEmpty;
          BlockNode* write = nullptr;
          CellChanges* out = changes != nullptr ? &job_changes[j] : nullptr;
          ScanUpdate::forEachCellInBlock(
              jobs[j].block_key, *jobs[j].cells, [&](const VoxelKey& key, const CellHits& hits) {
                const int i = block::indexOf(key);
                const bool known = read->voxels.isKnown(i);
                const float old_value = known ? read->voxels.log_odds[i] : 0.0F;
                const float new_value = updatedLogOdds(model, rule, old_value, hits);
                ++c.updated;
                if (known && new_value == old_value) return;
                if (write == nullptr) {
                  write = &store_->writable(*jobs[j].entry);
                  read = write;
                }
                if (!known) {
                  write->voxels.markKnown(i);
                  ++c.newly_known;
                }
                ++c.changed;
                if (out != nullptr) out->push_back({key, new_value, true});
                store(*write, i, new_value);
              });
        }
        return c;
      },
      [](Counts a, const Counts& b) {
        a.updated += b.updated;
        a.changed += b.changed;
        a.newly_known += b.newly_known;
        return a;
      });
  known_cells_ += total.newly_known;
  if (changes != nullptr) {
    for (auto& part : job_changes) changes->insert(changes->end(), part.begin(), part.end());
  }
  return {total.updated, total.changed};
}

std::size_t GridMap::clearBox(const VoxelKey& min, const VoxelKey& max, CellChanges* changes) {
  const VoxelKey bmin{static_cast<std::uint16_t>(min.x >> block::kShift),
                      static_cast<std::uint16_t>(min.y >> block::kShift),
                      static_cast<std::uint16_t>(min.z >> block::kShift)};
  const VoxelKey bmax{static_cast<std::uint16_t>(max.x >> block::kShift),
                      static_cast<std::uint16_t>(max.y >> block::kShift),
                      static_cast<std::uint16_t>(max.z >> block::kShift)};
  std::size_t erased = 0;
  auto clearIn = [&](BlockEntry& e) {
    const BlockNode* head = BlockStore::latest(e);
    if (head == nullptr) return;
    const VoxelKey corner = block::keyOf(e.key, 0);
    if ((corner.x >> block::kShift) < bmin.x || (corner.y >> block::kShift) < bmin.y ||
        (corner.z >> block::kShift) < bmin.z || (corner.x >> block::kShift) > bmax.x ||
        (corner.y >> block::kShift) > bmax.y || (corner.z >> block::kShift) > bmax.z) {
      return;
    }
    const int edge = block::kEdge - 1;
    const bool whole = corner.x >= min.x && corner.y >= min.y && corner.z >= min.z &&
                       corner.x + edge <= max.x && corner.y + edge <= max.y &&
                       corner.z + edge <= max.z;
    if (whole) {  // every cell goes: drop the block (its memory returns to the pool)
      erased += dropBlock(e, changes);
      return;
    }
    BlockNode* node = nullptr;
    block::forEachSetBit(head->voxels.known, [&](int i) {
      const VoxelKey k = block::keyOf(e.key, i);
      if (k.x < min.x || k.y < min.y || k.z < min.z || k.x > max.x || k.y > max.y || k.z > max.z) {
        return;
      }
      if (node == nullptr) node = &store_->writable(e);
      block::clearBit(node->voxels.known, i);
      block::clearBit(node->fully_free, i);
      ++erased;
      if (changes != nullptr) changes->push_back({k, 0.0F, false});
    });
    if (node != nullptr && block::countBits(node->voxels.known) == 0) (void)store_->drop(e);
  };
  // Walk the box's blocks when there are fewer of them than blocks in the map.
  const double box_blocks =
      (bmax.x - bmin.x + 1.0) * (bmax.y - bmin.y + 1.0) * (bmax.z - bmin.z + 1.0);
  if (box_blocks < static_cast<double>(store_->entryCount())) {
    for (unsigned z = bmin.z; z <= bmax.z; ++z) {
      for (unsigned y = bmin.y; y <= bmax.y; ++y) {
        for (unsigned x = bmin.x; x <= bmax.x; ++x) {
          const VoxelKey corner{static_cast<std::uint16_t>(x << block::kShift),
                                static_cast<std::uint16_t>(y << block::kShift),
                                static_cast<std::uint16_t>(z << block::kShift)};
          const std::uint64_t key = block::blockOf(corner);
          if (store_->latest(key) != nullptr) clearIn(store_->entry(key));
        }
      }
    }
  } else {
    store_->forEachEntryWriter([&](BlockEntry& e) { clearIn(e); });
  }
  known_cells_ -= erased;
  return erased;
}

std::size_t GridMap::dropBlock(BlockEntry& e, CellChanges* changes) {
  const BlockNode* head = BlockStore::latest(e);
  if (head == nullptr) return 0;
  const std::size_t cells = block::countBits(head->voxels.known);
  if (changes != nullptr) {
    block::forEachSetBit(head->voxels.known, [&](int i) {
      changes->push_back({block::keyOf(e.key, i), 0.0F, false});
    });
  }
  (void)store_->drop(e);
  return cells;
}

EvictStats GridMap::evictBlocks(const std::function<bool(const Point3f&)>& keep,
                                CellChanges* changes) {
  EvictStats stats;
  store_->forEachEntryWriter([&](BlockEntry& e) {
    if (BlockStore::latest(e) == nullptr) return;
    if (keep(block::centreOf(grid(), e.key))) return;
    const std::size_t cells = dropBlock(e, changes);
    known_cells_ -= cells;
    stats.cells += cells;
    ++stats.blocks;
  });
  return stats;
}

std::optional<float> GridMap::logOdds(const VoxelKey& key) const {
  const BlockNode* n = store_->latest(block::blockOf(key));
  if (n == nullptr) return std::nullopt;
  const int i = block::indexOf(key);
  if (!n->voxels.isKnown(i)) return std::nullopt;
  return n->voxels.log_odds[i];
}

void GridMap::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  store_->forEachEntryWriter([&](const BlockEntry& e) {
    const BlockNode* n = BlockStore::latest(e);
    if (n == nullptr) return;
    block::forEachSetBit(n->voxels.known,
                         [&](int i) { f(block::keyOf(e.key, i), n->voxels.log_odds[i]); });
  });
}

void GridMap::forEachFullyFreeBlock(
    const std::function<void(std::uint64_t, const block::BlockMask&)>& f) const {
  store_->forEachEntryWriter([&](const BlockEntry& e) {
    const BlockNode* n = BlockStore::latest(e);
    if (n != nullptr) f(e.key, n->fully_free);
  });
}

void GridMap::setLogOdds(const VoxelKey& key, float log_odds) {
  BlockNode& node = store_->writable(store_->entry(block::blockOf(key)));
  const int i = block::indexOf(key);
  if (!node.voxels.isKnown(i)) {
    node.voxels.markKnown(i);
    ++known_cells_;
  }
  store(node, i, log_odds);
}

void GridMap::erase(const VoxelKey& key) {
  const std::uint64_t bk = block::blockOf(key);
  const BlockNode* latest = store_->latest(bk);
  const int i = block::indexOf(key);
  if (latest == nullptr || !latest->voxels.isKnown(i)) return;
  BlockNode& node = store_->writable(store_->entry(bk));
  block::clearBit(node.voxels.known, i);
  block::clearBit(node.fully_free, i);
  --known_cells_;
}

void GridMap::applyChanges(const CellChanges& changes) {
  for (const CellChange& c : changes) {
    if (c.known) {
      setLogOdds(c.key, c.log_odds);
    } else {
      erase(c.key);
    }
  }
}

ApplyStats GridMap::assignBlocks(std::span<const BlockCells> blocks, const BlockValues& values_of,
                                 CellChanges* changes) {
  std::vector<BlockEntry*> entries(blocks.size());
  for (std::size_t j = 0; j < blocks.size(); ++j) entries[j] = &store_->entry(blocks[j].key);
  std::vector<CellChanges> block_changes(changes != nullptr ? blocks.size() : 0);
  struct Counts {
    std::size_t updated = 0, changed = 0, newly_known = 0;
  };
  static const BlockNode kEmpty{};
  const Counts total = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, blocks.size(), 16), Counts{},
      [&](const tbb::blocked_range<std::size_t>& range, Counts c) {
        std::array<float, block::kVoxels> values{};
        for (std::size_t j = range.begin(); j != range.end(); ++j) {
          const BlockCells& b = blocks[j];
          values_of(b.key, b.cells, values);
          const BlockNode* head = BlockStore::latest(*entries[j]);
          const BlockNode* read = head != nullptr ? head : &kEmpty;
          BlockNode* write = nullptr;  // the first change takes the writable node
          block::forEachSetBit(b.cells, [&](int i) {
            ++c.updated;
            const bool known = read->voxels.isKnown(i);
            if (known && read->voxels.log_odds[i] == values[i]) return;
            if (write == nullptr) {
              write = &store_->writable(*entries[j]);
              read = write;
            }
            if (!known) {
              write->voxels.markKnown(i);
              ++c.newly_known;
            }
            ++c.changed;
            store(*write, i, values[i]);
            if (changes != nullptr) block_changes[j].push_back({block::keyOf(b.key, i), values[i]});
          });
        }
        return c;
      },
      [](Counts a, const Counts& b) {
        a.updated += b.updated;
        a.changed += b.changed;
        a.newly_known += b.newly_known;
        return a;
      });
  known_cells_ += total.newly_known;
  if (changes != nullptr) {
    for (auto& part : block_changes) changes->insert(changes->end(), part.begin(), part.end());
  }
  return {total.updated, total.changed};
}

void GridMap::clear() {
  if (!store_->versioned()) {  // nobody reads older versions: drop everything at once
    store_->clearUnversioned();
    known_cells_ = 0;
    return;
  }
  // Readers keep their versions: drop every block from the next one.
  store_->forEachEntryWriter([&](BlockEntry& e) { (void)store_->drop(e); });
  known_cells_ = 0;
}

}  // namespace densemap
