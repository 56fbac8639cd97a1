#include "densemap/map/occupancy_decay.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include "densemap/map/grid_map.hpp"

namespace densemap {
namespace {

constexpr double kMaxSeconds = 1e6;

std::int64_t toMs(double seconds) { return std::llround(seconds * 1e3); }

std::int64_t floorMs(std::int64_t ns) {
  return ns >= 0 ? ns / 1'000'000 : -((-(ns + 1)) / 1'000'000) - 1;
}

}  // namespace

Expected<void> checkDecayOptions(const DecayOptions& o) {
  if (!(o.after_s >= 0.0 && o.after_s <= kMaxSeconds)) {
    return makeError("after_s must be in [0, 1e6] seconds");
  }
  if (!(o.period_s >= 0.001 && o.period_s <= kMaxSeconds)) {
    return makeError("period_s must be in [0.001, 1e6] seconds");
  }
  return {};
}

OccupancyDecay::OccupancyDecay(const DecayOptions& options)
    : options_(options),
      after_ms_(toMs(options.after_s)),
      period_ms_(std::max<std::int64_t>(1, toMs(options.period_s))) {}

OccupancyDecay::~OccupancyDecay() = default;

std::size_t OccupancyDecay::memoryBytes() const {
  // A hash node per block (key, pointer, next) besides the block itself.
  return blocks_.size() * (sizeof(Block) + 4 * sizeof(void*)) +
         blocks_.bucket_count() * sizeof(void*) + queue_.size() * sizeof(Entry);
}

std::int64_t OccupancyDecay::tick(std::int64_t now_ns) {
  latest_ = std::max(latest_, floorMs(now_ns));
  return latest_;
}

void OccupancyDecay::enqueue(std::uint64_t key, Block& b, std::int64_t due) {
  if (due >= b.queued) return;  // its queue entry comes first already
  b.queued = due;
  queue_.emplace(due, key);
}

void OccupancyDecay::setDue(Block& b, int i, std::int64_t due) {
  constexpr std::int64_t kSpan = std::numeric_limits<std::uint32_t>::max();
  if (due < b.base || due - b.base > kSpan) {
    // A new base: the earliest due time of the block (cells more than 2^32 ms older than
    // `due`, left by a caller that does not decay before it observes, move up to the span).
    std::int64_t base = due;
    block::forEachSetBit(b.tracked, [&](int j) {
      if (j != i) base = std::min(base, b.base + b.due[j]);
    });
    base = std::max(base, due - kSpan);
    block::forEachSetBit(b.tracked, [&](int j) {
      b.due[j] = static_cast<std::uint32_t>(std::clamp<std::int64_t>(b.base + b.due[j] - base, 0, kSpan));
    });
    b.base = base;
  }
  b.due[i] = static_cast<std::uint32_t>(due - b.base);
}

std::int64_t OccupancyDecay::firstDue(const Block& b) {
  std::int64_t first = kNever;
  block::forEachSetBit(b.tracked, [&](int i) { first = std::min(first, b.base + b.due[i]); });
  return first;
}

void OccupancyDecay::observe(std::span<const VoxelKey> hits, std::int64_t now_ns) {
  const std::int64_t due = tick(now_ns) + after_ms_;
  cache_.assign(kCacheSlots, {0, nullptr});
  for (const VoxelKey& key : hits) {
    const std::uint64_t bk = block::blockOf(key);
    auto& [cached_key, b] = cache_[(bk * 0x9E3779B97F4A7C15ULL) >> 52];
    if (b == nullptr || cached_key != bk) {
      auto& slot = blocks_[bk];
      if (!slot) {
        slot = std::make_unique<Block>();
        slot->base = due;
      }
      b = slot.get();
      cached_key = bk;
    }
    const int i = block::indexOf(key);
    setDue(*b, i, due);
    block::setBit(b->tracked, i);
    enqueue(bk, *b, due);
  }
}

DecayStats OccupancyDecay::decay(GridMap& map, std::int64_t now_ns, CellChanges* changes) {
  const std::int64_t now = tick(now_ns);
  std::vector<std::uint64_t> due_blocks;
  while (!queue_.empty() && queue_.top().first <= now) {
    const auto [due, key] = queue_.top();
    queue_.pop();
    const auto it = blocks_.find(key);
    if (it == blocks_.end() || it->second->queued != due) continue;  // superseded entry
    it->second->queued = kNever;
    due_blocks.push_back(key);
  }
  DecayStats stats;
  if (due_blocks.empty()) return stats;

  // Each due block on its own (its cells and times are its own; the map is only read), in
  // parallel on the map's runner; then, in order, the blocks go back in the queue or away.
  const SensorModel& model = map.sensorModel();
  const BlockStore& store = map.writerStore();
  const std::size_t n = due_blocks.size();
  std::vector<Block*> blocks(n);
  for (std::size_t j = 0; j < n; ++j) blocks[j] = blocks_.at(due_blocks[j]).get();
  std::vector<BlockCells> writes(n);
  std::vector<std::array<float, block::kVoxels>> values(n);
  std::atomic<std::size_t> stepped{0}, erased{0};
  map.runner().run(n, 8, [&](std::size_t begin, std::size_t end) {
    std::size_t my_stepped = 0, my_erased = 0;
    for (std::size_t j = begin; j != end; ++j) {
      Block& b = *blocks[j];
      const BlockNode* node = store.latest(due_blocks[j]);
      BlockCells& write = writes[j];
      write.key = due_blocks[j];
      std::array<float, block::kVoxels>& v = values[j];
      block::forEachSetBit(b.tracked, [&](int i) {
        const std::int64_t due = b.base + b.due[i];
        if (due > now) return;
        const float old =
            node != nullptr && node->voxels.isKnown(i) ? node->voxels.log_odds[i] : 0.0F;
        if (!SensorModel::isOccupied(old)) {  // unknown, free, or cleared by other means
          block::clearBit(b.tracked, i);
          return;
        }
        // One miss per period elapsed since it fell due; the loop ends once the cell leaves
        // the occupied class (at most clamp_max / |miss| + 1 steps).
        const std::int64_t steps = (now - due) / period_ms_ + 1;
        float value = old;
        bool gone = false;
        for (std::int64_t s = 0; s < steps; ++s) {
          value = model.updateBy(value, model.miss());
          if (!SensorModel::isOccupied(value)) {
            gone = true;
            break;
          }
        }
        block::setBit(write.cells, i);
        if (gone) {
          v[i] = std::numeric_limits<float>::quiet_NaN();  // assignBlocks: becomes unknown
          block::clearBit(b.tracked, i);
          ++my_erased;
        } else {
          v[i] = value;
          // Due after now, at most period_s on: within the block's span (setDue keeps it so).
          setDue(b, i, due + steps * period_ms_);
          ++my_stepped;
        }
      });
    }
    stepped += my_stepped;
    erased += my_erased;
  });
  stats.stepped = stepped.load();
  stats.erased = erased.load();
  std::size_t kept = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const std::int64_t first = firstDue(*blocks[j]);
    if (first == kNever) {
      blocks_.erase(due_blocks[j]);
    } else {
      enqueue(due_blocks[j], *blocks[j], first);
    }
    if (block::anyBit(writes[j].cells)) {
      if (kept != j) {
        writes[kept] = writes[j];
        values[kept] = values[j];
      }
      ++kept;
    }
  }
  writes.resize(kept);
  values.resize(kept);
  if (writes.empty()) return stats;
  std::unordered_map<std::uint64_t, std::size_t> index;
  index.reserve(writes.size());
  for (std::size_t j = 0; j < writes.size(); ++j) index.emplace(writes[j].key, j);
  (void)map.assignBlocks(
      writes,
      [&](std::uint64_t key, const block::BlockMask&, std::array<float, block::kVoxels>& out) {
        out = values[index.at(key)];
      },
      changes);
  return stats;
}

}  // namespace densemap
