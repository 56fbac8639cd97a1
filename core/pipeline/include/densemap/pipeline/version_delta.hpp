#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "densemap/map/occupancy_map.hpp"
#include "densemap/pipeline/map_view.hpp"

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
};

/// What changed from `base` to `next` in `blocks` (the blocks the versions between them wrote;
/// other blocks are taken as unchanged). Costs O(blocks), never O(map).
[[nodiscard]] VersionDelta diffVersions(const MapView& base, const MapView& next,
                                        std::span<const std::uint64_t> blocks);

/// Map tiles (densemap/map/tiles): cubes of 32^3 cells = 4^3 blocks.
inline constexpr int kTileBlockShift = 2;
[[nodiscard]] std::uint64_t tileOf(const VoxelKey& k);
[[nodiscard]] std::uint64_t tileOfBlock(std::uint64_t block_key);
/// The known cells of a tile at the view's version: x y z per cell and its log-odds. Reads the
/// tile's 64 blocks, never the rest of the map.
void readTile(const MapView& view, std::uint64_t tile_id, std::vector<std::uint16_t>& keys,
              std::vector<float>& log_odds);

}  // namespace densemap
