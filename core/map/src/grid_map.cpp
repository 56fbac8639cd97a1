#include "densemap/map/grid_map.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <vector>

namespace densemap {

GridMap::Slot& GridMap::slotFor(std::uint64_t block_key) {
  auto& slot = blocks_[block_key];
  if (!slot) slot = std::make_unique<Slot>();
  return *slot;
}

void GridMap::store(Slot& slot, int index, float log_odds) const {
  slot.voxels.log_odds[index] = log_odds;
  if (sensorModel().isFullyFree(log_odds)) {
    block::setBit(slot.fully_free, index);
  } else {
    block::clearBit(slot.fully_free, index);
  }
}

ApplyStats GridMap::apply(const ScanUpdate& update, CellChanges* changes) {
  struct Job {
    std::uint64_t block_key;
    Slot* slot;
    const ScanUpdate::Block* cells;
  };
  std::vector<Job> jobs;
  jobs.reserve(update.blocks().size());
  for (const auto& [block_key, cells] : update.blocks()) {
    jobs.push_back({block_key, &slotFor(block_key), &cells});
  }

  // Each job records its changes in its own slot; slots are concatenated in job order.
  std::vector<CellChanges> job_changes(changes != nullptr ? jobs.size() : 0);
  struct Counts {
    std::size_t updated = 0, changed = 0, newly_known = 0;
  };
  const SensorModel& model = sensorModel();
  const UpdateRule rule = update.rule();
  const Counts total = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, jobs.size(), 16), Counts{},
      [&](const tbb::blocked_range<std::size_t>& range, Counts c) {
        for (std::size_t j = range.begin(); j != range.end(); ++j) {
          Slot& slot = *jobs[j].slot;
          VoxelBlock& b = slot.voxels;
          CellChanges* out = changes != nullptr ? &job_changes[j] : nullptr;
          ScanUpdate::forEachCellInBlock(
              jobs[j].block_key, *jobs[j].cells, [&](const VoxelKey& key, const CellHits& hits) {
                const int i = block::indexOf(key);
                const bool known = b.isKnown(i);
                const float old_value = known ? b.log_odds[i] : 0.0F;
                const float new_value = updatedLogOdds(model, rule, old_value, hits);
                ++c.updated;
                if (!known) {
                  b.markKnown(i);
                  ++c.newly_known;
                }
                if (!known || new_value != old_value) {
                  ++c.changed;
                  if (out != nullptr) out->push_back({key, new_value, true});
                }
                store(slot, i, new_value);
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
  std::size_t erased = 0;
  for (auto& [block_key, slot] : blocks_) {
    VoxelBlock& b = slot->voxels;
    for (int w = 0; w < block::kMaskWords; ++w) {
      std::uint64_t bits = b.known[w];
      while (bits != 0) {
        const int bit = std::countr_zero(bits);
        bits &= bits - 1;
        const int i = w * 64 + bit;
        const VoxelKey k = block::keyOf(block_key, i);
        if (k.x < min.x || k.y < min.y || k.z < min.z || k.x > max.x || k.y > max.y ||
            k.z > max.z) {
          continue;
        }
        block::clearBit(b.known, i);
        block::clearBit(slot->fully_free, i);
        ++erased;
        if (changes != nullptr) changes->push_back({k, 0.0F, false});
      }
    }
  }
  known_cells_ -= erased;
  return erased;
}

std::optional<float> GridMap::logOdds(const VoxelKey& key) const {
  const auto it = blocks_.find(block::blockOf(key));
  if (it == blocks_.end()) return std::nullopt;
  const int i = block::indexOf(key);
  if (!it->second->voxels.isKnown(i)) return std::nullopt;
  return it->second->voxels.log_odds[i];
}

void GridMap::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  for (const auto& [block_key, slot] : blocks_) {
    const VoxelBlock& b = slot->voxels;
    for (int i = 0; i < block::kVoxels; ++i) {
      if (b.isKnown(i)) f(block::keyOf(block_key, i), b.log_odds[i]);
    }
  }
}

void GridMap::forEachFullyFreeBlock(
    const std::function<void(std::uint64_t, const block::BlockMask&)>& f) const {
  for (const auto& [block_key, slot] : blocks_) f(block_key, slot->fully_free);
}

void GridMap::setLogOdds(const VoxelKey& key, float log_odds) {
  Slot& slot = slotFor(block::blockOf(key));
  const int i = block::indexOf(key);
  if (!slot.voxels.isKnown(i)) {
    slot.voxels.markKnown(i);
    ++known_cells_;
  }
  store(slot, i, log_odds);
}

std::size_t GridMap::memoryBytes() const {
  // Block payload + the hash node (key, pointer, next pointer, cached hash) + buckets.
  constexpr std::size_t kNodeBytes = sizeof(std::uint64_t) + 3 * sizeof(void*);
  return blocks_.size() * (sizeof(Slot) + kNodeBytes) + blocks_.bucket_count() * sizeof(void*) +
         sizeof(*this);
}

void GridMap::clear() {
  blocks_.clear();
  known_cells_ = 0;
}

}  // namespace densemap
