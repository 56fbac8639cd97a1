#pragma once

#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

#include "densemap/map/occupancy_map.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

/// The cells that differ between two versions, grouped by 8^3 block (the map/delta wire
/// layout): block i owns cells [block_ends[i-1], block_ends[i]) of `cells` (index in its block)
/// and `log_odds` (NaN: the cell was erased). About 6 bytes per cell against 10 for full keys.
struct VersionDelta {
  std::vector<std::uint64_t> block_keys;
  std::vector<std::uint32_t> block_ends;
  std::vector<std::uint16_t> cells;
  std::vector<float> log_odds;

  [[nodiscard]] std::size_t size() const { return cells.size(); }
  /// Lengths agree, block ends increase within `cells`, cell indices fit a block (check what
  /// came off the wire before reading it).
  [[nodiscard]] bool wellFormed() const;
  /// The cells as a change list (key, value, known).
  [[nodiscard]] CellChanges changes() const;
  /// Ends block `block_key`: the cells appended since the previous block are its cells (a
  /// block without cells gets no entry).
  void closeBlock(std::uint64_t block_key);
};

/// What changed from `base` to `next` in `blocks` (the blocks the versions between them wrote;
/// other blocks are taken as unchanged). Costs O(blocks), never O(map).
[[nodiscard]] VersionDelta diffVersions(const MapView& base, const MapView& next,
                                        std::span<const std::uint64_t> blocks);

/// Map tiles (densemap/map/tiles): cubes of 32^3 cells = 4^3 blocks.
[[nodiscard]] std::uint64_t tileOf(const VoxelKey& k);
[[nodiscard]] std::uint64_t tileOfBlock(std::uint64_t block_key);
/// The blocks with contents at the view's version, by tile (one walk of the map; each list
/// sorted).
[[nodiscard]] std::unordered_map<std::uint64_t, std::vector<std::uint64_t>> tilesOf(
    const MapView& view);
/// Every known cell of `blocks` at the view's version, in the VersionDelta layout (the
/// map/tiles payload).
[[nodiscard]] VersionDelta cellsOf(const MapView& view, std::span<const std::uint64_t> blocks);

}  // namespace densemap
