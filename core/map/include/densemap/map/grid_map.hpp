#pragma once

#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "densemap/map/block_store.hpp"
#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// What GridMap::evictBlocks dropped.
struct EvictStats {
  std::size_t blocks = 0;
  std::size_t cells = 0;
};

/// The fast backend: a sparse hash of 8^3 voxel blocks (Bonxai/voxblox style) kept in a
/// BlockStore, so readers can hold published versions of this very map (no second copy).
/// `apply` creates missing blocks serially, then updates blocks in parallel (TBB), each block
/// owned by one task, so the result is the same for any number of threads.
/// Thread-safety: single writer (OccupancyMap); `publishVersion` hands readers a version they
/// read through `store()` from any thread.
class GridMap final : public OccupancyMap {
 public:
  GridMap(double resolution_m, const SensorModel& model)
      : OccupancyMap(resolution_m, model), store_(std::make_shared<BlockStore>()) {}

  [[nodiscard]] Backend backend() const override { return Backend::kGrid; }
  ApplyStats apply(const ScanUpdate& update, CellChanges* changes = nullptr) override;
  std::size_t clearBox(const VoxelKey& min, const VoxelKey& max,
                       CellChanges* changes = nullptr) override;
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) const override;
  void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const override;
  void setLogOdds(const VoxelKey& key, float log_odds) override;
  void appendFullyFreeBlocks(const block::BlockBox& box,
                             std::vector<FullyFreeBlock>& out) const override;
  [[nodiscard]] std::size_t knownCells() const override { return known_cells_; }
  [[nodiscard]] std::size_t memoryBytes() const override { return store_->memoryBytes(); }
  void clear() override;

  /// Drops every block whose centre `keep` rejects (a bounded window or box around the robot):
  /// their cells become unknown (appended to `changes` as erased) and their memory returns to
  /// the pool once no reader holds an older version. `keep` must hold on every block centre of
  /// a box of blocks when it holds on the box's 8 corner blocks (a ball, an axis-aligned box,
  /// their intersection: a test per axis, monotone away from its centre), so a region of 8^3
  /// blocks whose corners are kept is passed over whole: the cost follows the regions and the
  /// blocks near the window's edge, not every block of the map.
  /// A dense map's evidence in the dropped blocks' entries goes with them.
  EvictStats evictBlocks(const std::function<bool(const Point3f&)>& keep,
                         CellChanges* changes = nullptr);

  /// Forgets one cell (a no-op for an unknown cell).
  void erase(const VoxelKey& key);
  /// Applies a change list (values set, erased cells forgotten): how a mirror follows a map.
  void applyChanges(const CellChanges& changes);
  /// Fills `values[cell]` for the cells of a block's mask (assignBlocks); called from parallel
  /// tasks, one block at a time each.
  using BlockValues = std::function<void(std::uint64_t block_key, const block::BlockMask& cells,
                                         std::array<float, block::kVoxels>& values)>;
  /// Sets each block's cells to the values `values_of` gives them, in parallel, a block per
  /// task (missing blocks created first, serially, so the result is the same for any number
  /// of threads); a known cell whose value is unchanged is not written, a cell given NaN
  /// becomes unknown (a block left with no known cell is dropped). `blocks` has each block
  /// once; changes come in its order. How a dense map's published grid follows its evidence,
  /// and how occupied cells decay (OccupancyDecay).
  ApplyStats assignBlocks(std::span<const BlockCells> blocks, const BlockValues& values_of,
                          CellChanges* changes = nullptr);

  [[nodiscard]] std::size_t blockCount() const { return store_->entryCount(); }

  /// The widest lanes apply and assignBlocks may write with: 512 (AVX-512), 256 (AVX2) or 0
  /// (a cell at a time); the processor's own widest applies too. Every width writes the same
  /// map and the same changes; tests compare them on one machine.
  void limitLanes(int bits) { lane_bits_ = bits; }

  /// Versioning (MapView): before the first publish, the version the contents belong to.
  void startVersionsAt(std::uint64_t version) { store_->startAt(version); }
  /// Pre-faults room for `blocks` more blocks in the node pool (see BlockStore::reserve).
  void reserveBlocks(std::size_t blocks) { store_->reserve(blocks); }
  /// Ends the version being written; readers of it hold the returned pin.
  BlockStore::Published publishVersion() { return store_->publish(); }
  /// Live versions instead (BlockStore::startLive, advance): in place, readers wait.
  void startLiveVersions() { store_->startLive(); }
  BlockStore::Published advanceVersion() { return store_->advance(); }
  [[nodiscard]] std::shared_ptr<const BlockStore> store() const { return store_; }
  /// The writer's own access to the store: a dense kernel map keeps its evidence in the
  /// blocks' entries (BlockStore::evidence), so one index serves both.
  [[nodiscard]] BlockStore& writerStore() { return *store_; }

 private:
  void store(BlockNode& node, int index, float log_odds) const;
  struct BlockWriter;  // one block's writes in a parallel update (grid_map.cpp)
  /// Runs write_block(j, writer) for every entry in parallel, a block per task; counts, newly
  /// known cells and the changes (in entry order) gathered.
  /// `cells_of(j)`, when given, is the mask of the cells block j's writes touch: their lines of
  /// the block's values, and of its evidence where it holds a dense map's, are fetched ahead
  /// too.
  template <class WriteBlock, class CellsOf = std::nullptr_t>
  ApplyStats writeBlocks(std::span<BlockEntry* const> entries, CellChanges* changes,
                         WriteBlock&& write_block, CellsOf&& cells_of = nullptr);
  /// Drops a block (BlockStore::drop); returns its known cells. known_cells_ is the caller's.
  std::size_t dropBlock(BlockEntry& entry, CellChanges* changes);

  /// The entries of an update's blocks, in its order (apply, assignBlocks): kept from scan to
  /// scan, so that a scan allocates nothing for them (each allocation would walk the
  /// allocator's free chunks whenever another part of the process has just freed many, as
  /// OctoMap does in the benchmark's lane).
  std::vector<BlockEntry*>& writeEntries(std::size_t n) {
    write_entries_.resize(n);
    return write_entries_;
  }

  std::shared_ptr<BlockStore> store_;
  std::size_t known_cells_ = 0;
  std::vector<BlockEntry*> write_entries_;
  int lane_bits_ = 512;
};

}  // namespace densemap
