#pragma once

#include <memory>
#include <unordered_map>

#include "densemap/map/occupancy_map.hpp"
#include "densemap/map/voxel_block.hpp"

namespace densemap {

/// The fast backend: a sparse hash of 8^3 voxel blocks (Bonxai/voxblox style).
/// `apply` creates missing blocks serially, then updates blocks in parallel (TBB), each block
/// owned by one task, so the result is the same for any number of threads.
class GridMap final : public OccupancyMap {
 public:
  GridMap(double resolution_m, const SensorModel& model) : OccupancyMap(resolution_m, model) {}

  [[nodiscard]] Backend backend() const override { return Backend::kGrid; }
  ApplyStats apply(const ScanUpdate& update, CellChanges* changes = nullptr) override;
  std::size_t clearBox(const VoxelKey& min, const VoxelKey& max,
                       CellChanges* changes = nullptr) override;
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) const override;
  void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const override;
  void setLogOdds(const VoxelKey& key, float log_odds) override;
  void forEachFullyFreeBlock(
      const std::function<void(std::uint64_t, const block::BlockMask&)>& f) const override;
  [[nodiscard]] std::size_t knownCells() const override { return known_cells_; }
  [[nodiscard]] std::size_t memoryBytes() const override;
  void clear() override;

  [[nodiscard]] std::size_t blockCount() const { return blocks_.size(); }

 private:
  struct Slot {
    VoxelBlock voxels;
    block::BlockMask fully_free{};  // known cells at the lower clamping bound
  };
  Slot& slotFor(std::uint64_t block_key);
  void store(Slot& slot, int index, float log_odds) const;

  std::unordered_map<std::uint64_t, std::unique_ptr<Slot>> blocks_;
  std::size_t known_cells_ = 0;
};

}  // namespace densemap
