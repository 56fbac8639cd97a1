#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include "densemap/map/block_store.hpp"
#include "densemap/map/grid_map.hpp"

namespace densemap {

/// One published version of the map, read from the map's own block store (no copy): the
/// blocks as that version left them, whatever the writer has done since. Holding the view
/// holds the version (its pin); dropping it lets the writer's superseded blocks go.
/// Creating a view costs O(1); the writer pays O(changed blocks) per version (BlockStore).
/// Thread-safety: immutable; every method is safe from any thread.
class MapView {
 public:
  MapView(std::shared_ptr<const BlockStore> store, std::shared_ptr<const void> pin,
          double resolution_m, std::uint64_t version, std::size_t known_cells,
          std::size_t memory_bytes)
      : grid_(resolution_m),
        version_(version),
        known_cells_(known_cells),
        memory_bytes_(memory_bytes),
        store_(std::move(store)),
        pin_(std::move(pin)) {}

  /// Publishes the version `map` is writing and returns its view. `other_bytes`: storage held
  /// elsewhere for the same map (the octree a mirrored GridMap follows), added to the view's
  /// memoryBytes(); `written_blocks`, when given, receives the blocks the version wrote.
  [[nodiscard]] static std::shared_ptr<const MapView> publish(
      GridMap& map, std::size_t other_bytes = 0,
      std::vector<std::uint64_t>* written_blocks = nullptr);
  /// Ends the version `map` is writing in place (live versions, GridMap::startLiveVersions) and
  /// returns a view of its latest contents. The view holds no version: it is valid only until
  /// the writer writes again (its readers and the writer take turns).
  [[nodiscard]] static std::shared_ptr<const MapView> advanceLive(
      GridMap& map, std::size_t other_bytes = 0,
      std::vector<std::uint64_t>* written_blocks = nullptr);
  /// A view of a copy of `map` (any backend) at `version`: for loaded files and tests.
  [[nodiscard]] static std::shared_ptr<const MapView> fromMap(const OccupancyMap& map,
                                                              std::uint64_t version);

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  [[nodiscard]] std::uint64_t version() const { return version_; }
  [[nodiscard]] std::size_t knownCells() const { return known_cells_; }
  /// Bytes the map's storage held when this version was published.
  [[nodiscard]] std::size_t memoryBytes() const { return memory_bytes_; }
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) const;
  /// The block `block_key` as of this version, or null when it had no contents.
  [[nodiscard]] const VoxelBlock* block(std::uint64_t block_key) const {
    const BlockNode* n = store_->find(block_key, version_);
    return n != nullptr ? &n->voxels : nullptr;
  }
  void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const;
  /// Calls f(block_key, block) for every block with contents at this version.
  void forEachBlock(const std::function<void(std::uint64_t, const VoxelBlock&)>& f) const;

 private:
  VoxelGrid grid_;
  std::uint64_t version_;
  std::size_t known_cells_;
  std::size_t memory_bytes_;
  std::shared_ptr<const BlockStore> store_;
  std::shared_ptr<const void> pin_;  // after store_: released first
};

}  // namespace densemap
