#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <unordered_map>

#include "densemap/map/occupancy_map.hpp"
#include "densemap/map/voxel_block.hpp"

namespace densemap {

/// An immutable, versioned copy of the map that readers query while integration goes on.
/// Blocks are shared between consecutive versions; a new version copies only the block table
/// and the blocks a scan changed (copy-on-write), so publishing costs O(blocks) pointer copies
/// plus O(changed blocks), and readers never wait for the writer.
/// Thread-safety: immutable; every method is safe from any thread.
class MapView {
 public:
  using Blocks = std::unordered_map<std::uint64_t, std::shared_ptr<const VoxelBlock>>;

  MapView(double resolution_m, std::uint64_t version, Blocks blocks, std::size_t known_cells)
      : grid_(resolution_m),
        version_(version),
        blocks_(std::move(blocks)),
        known_cells_(known_cells) {}

  /// A view holding every cell of `map`.
  [[nodiscard]] static std::shared_ptr<const MapView> fromMap(const OccupancyMap& map,
                                                              std::uint64_t version);
  /// The next version: this one with `changes` applied.
  [[nodiscard]] std::shared_ptr<const MapView> withChanges(const CellChanges& changes,
                                                           std::uint64_t new_version) const;

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  [[nodiscard]] std::uint64_t version() const { return version_; }
  [[nodiscard]] std::size_t knownCells() const { return known_cells_; }
  [[nodiscard]] std::size_t blockCount() const { return blocks_.size(); }
  [[nodiscard]] std::optional<float> logOdds(const VoxelKey& key) const;
  void forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const;

 private:
  VoxelGrid grid_;
  std::uint64_t version_;
  Blocks blocks_;
  std::size_t known_cells_;
};

}  // namespace densemap
