#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <queue>
#include <span>
#include <unordered_map>
#include <utility>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/map/cell_change.hpp"
#include "densemap/map/decay_options.hpp"

namespace densemap {

class GridMap;

/// after_s and period_s finite and in range; errors name the field (after_s, period_s).
[[nodiscard]] Expected<void> checkDecayOptions(const DecayOptions& options);

/// What one decay pass did.
struct DecayStats {
  std::size_t stepped = 0;  // cells that took a miss and stayed occupied
  std::size_t erased = 0;   // cells that became unknown
};

/// A map that forgets what moved: occupied cells not hit for `after_s` take one miss update
/// (the sensor model's miss, clamped as any update) every `period_s` while they stay occupied
/// (log-odds > 0); the step that would leave a cell at or below 0 makes it unknown instead. A
/// hit starts the cell's wait again; rays through it clear it as before. This is OctoMap's
/// OcTreeStamped::degradeOutdatedNodes (a miss per pass for occupied nodes older than a
/// threshold) at a fixed rate, ending at unknown rather than at a free value, and done per
/// block that is due rather than by walking the map.
///
/// Each block with a cell hit recently holds a due time per cell (milliseconds, 2 KiB a
/// block); the blocks wait in a queue ordered by their earliest due time, so a pass costs
/// the blocks that are due, not the map. Cells the map holds without a hit (a loaded snapshot)
/// are not tracked until hit. Cells erased or cleared by other means are let go when due.
///
/// Thread-safety: one thread at a time (the map's writer).
class OccupancyDecay {
 public:
  explicit OccupancyDecay(const DecayOptions& options);
  ~OccupancyDecay();
  OccupancyDecay(const OccupancyDecay&) = delete;
  OccupancyDecay& operator=(const OccupancyDecay&) = delete;

  /// Cells hit by a scan at `now_ns`: each waits `after_s` from now before it decays.
  void observe(std::span<const VoxelKey> hits, std::int64_t now_ns);
  /// Applies every step due at `now_ns` to `map` (one version's writes, appended to `changes`
  /// when given). Times before the latest seen count as the latest (the clock never runs back).
  DecayStats decay(GridMap& map, std::int64_t now_ns, CellChanges* changes = nullptr);

  [[nodiscard]] const DecayOptions& options() const { return options_; }
  /// Blocks with tracked cells, and the bytes the tracker holds.
  [[nodiscard]] std::size_t trackedBlocks() const { return blocks_.size(); }
  [[nodiscard]] std::size_t memoryBytes() const;

 private:
  /// A block's tracked cells and their due times: milliseconds after the block's base (a
  /// decay pass leaves every tracked cell due after the pass, so they span at most after_s +
  /// period_s, well inside 32 bits).
  struct Block {
    block::BlockMask tracked{};
    std::int64_t base = 0;                             // ms
    std::array<std::uint32_t, block::kVoxels> due{};  // ms after base
    std::int64_t queued = kNever;                      // due time of its live queue entry
  };
  static constexpr std::int64_t kNever = std::numeric_limits<std::int64_t>::max();
  using Entry = std::pair<std::int64_t, std::uint64_t>;  // due (ms), block key

  /// The clock (ms) at `now_ns`, held monotone.
  std::int64_t tick(std::int64_t now_ns);
  void enqueue(std::uint64_t key, Block& b, std::int64_t due);
  /// Sets cell i's due time, moving the block's base when the offset would not fit.
  static void setDue(Block& b, int i, std::int64_t due);
  [[nodiscard]] static std::int64_t firstDue(const Block& b);

  DecayOptions options_;
  std::int64_t after_ms_;
  std::int64_t period_ms_;
  std::int64_t latest_ = std::numeric_limits<std::int64_t>::min();  // the clock, ms
  std::unordered_map<std::uint64_t, std::unique_ptr<Block>> blocks_;
  /// observe()'s direct-mapped cache of blocks_ (a scan's hits come back to the same blocks
  /// column after column): cleared at each observe, as decay() may erase blocks.
  static constexpr std::size_t kCacheSlots = 4096;
  std::vector<std::pair<std::uint64_t, Block*>> cache_;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue_;
};

}  // namespace densemap
