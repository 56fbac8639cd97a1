#pragma once

#include <array>
#include <bit>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/geometry/chunk_runner.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/planner/flat_map.hpp"
#include "densemap/query/map_view.hpp"

namespace densemap {

struct DistanceFieldOptions {
  /// Distances are exact up to this (metres) and reported as this beyond it. At most 28 cells.
  double max_distance_m = 2.0;
};

/// A cell as integer coordinates (its key's, widened so that offsets may leave the key range).
struct CellCoord {
  int x = 0, y = 0, z = 0;
  [[nodiscard]] static CellCoord of(const VoxelKey& k) { return {k.x, k.y, k.z}; }
  [[nodiscard]] bool inRange() const {
    return x >= 0 && x <= 0xffff && y >= 0 && y <= 0xffff && z >= 0 && z <= 0xffff;
  }
  [[nodiscard]] VoxelKey key() const {
    return {static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
            static_cast<std::uint16_t>(z)};
  }
};

/// What one update did.
struct DistanceUpdateStats {
  std::size_t added = 0;         // cells that became occupied
  std::size_t removed = 0;       // cells that stopped being occupied
  std::size_t recomputed = 0;    // cells whose nearest occupied cell was removed, searched anew
  std::size_t field_blocks = 0;  // blocks of the field afterwards
};

/// The Euclidean distance from every cell centre to the nearest occupied cell centre of a map,
/// truncated at a maximum distance, kept current by updates that cost what the scan changed.
///
/// Values are squared distances in cells (integers, so exact): a cell farther than the
/// maximum from every occupied cell holds kFar and needs no storage. A block stores them in
/// one byte a cell when the squared maximum is below 255 (up to 15 cells: 2 m at 0.2 m), else
/// in two. An update takes the map
/// blocks a scan wrote or dropped, compares their occupied cells with the ones the field was
/// built from and, for each cell that changed class:
/// - one that became occupied lowers every cell of its ball (radius: the maximum) to its
///   distance where that is smaller;
/// - one that stopped being occupied marks the cells of its ball whose value was its distance;
///   each marked cell is searched anew, row by row of its ball, nearest rows first, over the
///   occupied cells as they are now.
/// Every other cell keeps a value some unchanged occupied cell still attains, or an added one
/// lowered it: the field after an update equals the field built from scratch, cell for cell.
/// Blocks of the field left with no finite cell are freed, so eviction of the map frees the
/// field with it.
///
/// Thread-safety: update() and clear() are writers; the const methods may run side by side
/// with each other but not with a writer.
class DistanceField {
 public:
  static constexpr std::uint16_t kFar = 0xffff;
  static constexpr int kMaxRadiusCells = 28;

  /// An error when max_distance_m is not finite, not positive, or more than 28 cells.
  [[nodiscard]] static Expected<DistanceField> create(double resolution_m,
                                                      const DistanceFieldOptions& options);

  /// Brings the field up to date with `view` for `blocks`: every block whose occupied cells
  /// may have changed since the last update (written or dropped). Blocks not named must be
  /// unchanged. The blocks of the field run on `runner` (each task writes its own).
  DistanceUpdateStats update(const MapView& view, std::span<const std::uint64_t> blocks,
                             const ChunkRunner& runner = serialRunner());
  /// Builds the field of every block `view` holds (after clear()).
  DistanceUpdateStats rebuild(const MapView& view, const ChunkRunner& runner = serialRunner());
  void clear();

  /// The squared distance (cells^2) from `cell` to the nearest occupied cell centre, or kFar.
  [[nodiscard]] std::uint16_t distanceSquared(const VoxelKey& cell) const;
  /// The nearest occupied cell to `cell` (one of them on a tie), or none within the maximum.
  [[nodiscard]] std::optional<VoxelKey> nearestOccupied(const VoxelKey& cell) const;

  [[nodiscard]] double resolution() const { return resolution_m_; }
  [[nodiscard]] double maxDistance() const { return options_.max_distance_m; }
  /// Squared maximum distance in cells^2 (largest exact value) and its radius in whole cells.
  [[nodiscard]] std::uint32_t radiusSquared() const { return radius2_; }
  [[nodiscard]] int radius() const { return radius_; }
  [[nodiscard]] std::size_t blocks() const {
    return narrow_ ? narrow_blocks_.size() : wide_blocks_.size();
  }
  [[nodiscard]] std::size_t memoryBytes() const;

  /// Whether a stored value (forEachBlockInLayer's, of either width) is beyond the maximum.
  template <class T>
  [[nodiscard]] static bool isFar(T v) {
    return v == std::numeric_limits<T>::max();
  }

  /// Calls f(cell, squared distance) for every finite cell of the field.
  template <class F>
  void forEachFinite(F&& f) const {
    withBlocks([&](const auto& blocks) {
      blocks.forEach([&](std::uint64_t key, const auto& b) {
        for (int i = 0; i < block::kVoxels; ++i) {
          if (!isFar(b->d2[i])) f(block::keyOf(key, i), static_cast<std::uint16_t>(b->d2[i]));
        }
      });
    });
  }

  /// Calls f(block key, its 512 squared distances: a std::array of uint8_t or uint16_t, isFar
  /// telling the far ones) for every block of the field whose z block coordinate is `block_z`
  /// (a walk over the field's blocks).
  template <class F>
  void forEachBlockInLayer(int block_z, F&& f) const {
    withBlocks([&](const auto& blocks) {
      blocks.forEach([&](std::uint64_t key, const auto& b) {
        if (static_cast<int>(block::coordsOf(key)[2]) == block_z) f(key, b->d2);
      });
    });
  }

  /// The rows of a ball: (dy, dz, h = dy^2 + dz^2, half-length in x), nearest first.
  struct BallRow {
    int dy, dz;
    std::uint32_t h;
    int ext;
  };
  [[nodiscard]] const std::vector<BallRow>& ballRows() const { return rows_; }

 private:
  /// A block of the field: squared distances of width T (isFar: none within the maximum).
  template <class T>
  struct Block {
    std::array<T, block::kVoxels> d2;
    Block() { d2.fill(std::numeric_limits<T>::max()); }
  };
  template <class T>
  using Blocks = FlatMap<std::unique_ptr<Block<T>>>;
  /// f(the blocks) of the field's width.
  template <class F>
  decltype(auto) withBlocks(F&& f) const {
    return narrow_ ? f(narrow_blocks_) : f(wide_blocks_);
  }
  template <class F>
  decltype(auto) withBlocks(F&& f) {
    return narrow_ ? f(narrow_blocks_) : f(wide_blocks_);
  }
  /// The changed cells whose ball reaches one block of the field, and what they did to it.
  /// Part of an x-row of one block that a changed cell's ball reaches: cells xa .. xb (in the
  /// block) of row `row` (y | z << 3 in the block), at squared distance h + (x - sx)^2.
  struct Segment {
    std::uint64_t block;
    std::uint16_t h;
    std::int16_t sx;
    std::uint8_t row, xa, xb;
    bool add;
  };
  /// One block of the field and its segments (contiguous in the update's sorted list).
  template <class T>
  struct Target {
    std::uint64_t key;
    Block<T>* block;
    const Segment* segments;
    std::size_t count;
    block::BlockMask marked;  // cells whose nearest occupied cell was removed
    bool any_marked;
  };
  DistanceField(double resolution_m, const DistanceFieldOptions& options);
  /// The segments of the changed cell s's ball that s may be nearest to (`near`: scratch).
  void segmentsOf(const CellCoord& s, bool add, std::vector<Segment>& out,
                  std::vector<std::array<int, 4>>& near) const;
  /// Lowers the block's cells to the added cells' distances and marks those whose value was
  /// a removed cell's distance.
  template <class T>
  void stampBlock(Target<T>& t) const;
  /// Searches the marked cells anew in a window of the occupied cells around the block (the
  /// block grown by the radius, one 64-bit word per x-row); returns how many.
  template <class T>
  std::size_t recomputeBlock(Target<T>& t, std::vector<std::uint64_t>& window) const;
  /// Applies one batch of changed cells (already recorded in sources_).
  void apply(const std::vector<CellCoord>& added, const std::vector<CellCoord>& removed,
             DistanceUpdateStats& stats, const ChunkRunner& runner);
  /// apply()'s second half: the segments (grouped by block: group g is
  /// segments[group_start[g] .. group_start[g + 1])) stamped into `blocks`, the marked cells
  /// searched anew, blocks left with no finite cell freed.
  template <class T>
  void applySegments(Blocks<T>& blocks, std::vector<Segment>& segments,
                     const std::vector<std::uint64_t>& group_keys,
                     const std::vector<std::size_t>& group_start, DistanceUpdateStats& stats,
                     const ChunkRunner& runner);

  double resolution_m_;
  DistanceFieldOptions options_;
  int radius_ = 0;
  std::uint32_t radius2_ = 0;
  std::vector<BallRow> rows_;
  std::vector<int> ext_;  // ext_[h]: the ball's half-length in x on a row with dy^2 + dz^2 = h
  /// The offsets at each squared distance d2 <= radius2_: shell_offsets_[shell_begin_[d2] ..
  /// shell_begin_[d2 + 1]) (the lattice points of that sphere; nearestOccupied's candidates).
  std::vector<std::array<std::int8_t, 3>> shell_offsets_;
  std::vector<std::uint32_t> shell_begin_;
  bool narrow_ = false;  // radius2_ < 255: one byte a cell
  Blocks<std::uint8_t> narrow_blocks_;
  Blocks<std::uint16_t> wide_blocks_;
  FlatMap<block::BlockMask> sources_;  // occupied cells per block (blocks with any)
};

/// The squared distance (cells^2) from `c` to the nearest cell whose bit `row(cx, y, z, ext)`
/// sets, searched over the rows of `rows` (nearest first) while below `bound2`; `row` returns
/// the bits of x in [cx - 31, cx + 32] (bit 31 is cx), of which only [cx - ext, cx + ext] count.
/// Returns bound2 when none is nearer, and the offset of the one found in `offset`. The search
/// stops at the first cell found at `enough` or nearer (a lower bound the caller knows: none
/// can be nearer).
template <class RowBits>
[[nodiscard]] std::uint32_t nearestInRows(const CellCoord& c, std::uint32_t bound2,
                                          std::span<const DistanceField::BallRow> rows,
                                          RowBits&& row, std::array<int, 3>* offset = nullptr,
                                          std::uint32_t enough = 0) {
  std::uint32_t best = bound2;
  for (const DistanceField::BallRow& r : rows) {
    if (r.h >= best) break;
    const std::uint64_t bits = row(c.x, c.y + r.dy, c.z + r.dz, r.ext);
    if (bits == 0) continue;
    // Nearest set bit to bit 31, up (x >= cx) and down (x < cx).
    int dx = 64;
    int sign = 1;
    if (const std::uint64_t up = bits >> 31; up != 0) dx = std::countr_zero(up);
    if (const std::uint64_t down = bits << 33; down != 0) {
      const int d = std::countl_zero(down) + 1;
      if (d < dx) {
        dx = d;
        sign = -1;
      }
    }
    if (dx > r.ext) continue;
    const std::uint32_t d2 = r.h + static_cast<std::uint32_t>(dx * dx);
    if (d2 < best) {
      best = d2;
      if (offset != nullptr) *offset = {sign * dx, r.dy, r.dz};
      if (best <= enough) break;
    }
  }
  return best;
}

}  // namespace densemap
