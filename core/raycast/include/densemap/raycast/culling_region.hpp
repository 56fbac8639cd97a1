#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "densemap/map/occupancy_map.hpp"

namespace densemap {

/// An axis-aligned box of voxel keys, bounds included.
struct KeyBox {
  VoxelKey min;
  VoxelKey max;
};

/// The culling region of one scan (dissertation Sec. 2.3.5, Alg. 3): voxels from which every
/// traversal back to the sensor's voxel O crosses only fully-free voxels (at the lower clamping
/// bound), so free updates there cannot change the map.
///
/// A voxel C is in the region iff it is fully free, is not ended in by a ray of this scan (so
/// the region also stays exact under UpdateRule::kPerRay, where such a voxel's free count
/// matters), and each "test cell" — C moved one step toward O along an axis where C differs
/// from O — is in the region; O itself needs only to be fully free. Alg. 3 grows this set by a
/// breadth-first search from O; here the same fixed point is computed by one sweep outward from
/// O over a dense bit grid of the scan's box, a row of voxels along x at a time (the x-test
/// becomes "the run of bits containing O's column"), which costs a few word operations per row.
///
/// Immutable after build(); `contains` is thread-safe.
class CullingRegion {
 public:
  /// Builds the region inside `box` (which must contain `origin`; voxels outside are never in
  /// the region). `hit` lists the voxels rays of this scan end in.
  /// `frame`, when given, must contain `box`: the query bricks then cover the blocks of
  /// `frame` (voxels outside `box` are not in the region), so that a DenseMarks reset to the
  /// same box shares their indexing (see sharesFrame and culledAt).
  /// `growable` (UpdateRule::kSet only): the box is loaded even when the region is empty (the
  /// sensor's voxel not fully free), and kept for grow().
  void build(const OccupancyMap& map, const VoxelKey& origin, const KeyBox& box,
             std::span<const VoxelKey> hit, const KeyBox* frame = nullptr, bool growable = false);

  /// Under UpdateRule::kSet only: grows the region (built growable) by voxels this scan has
  /// already marked free (`covered`: blocks' masks, ORed into the earlier calls'): the region is
  /// then the voxels fully free or marked whose test cells are in it, so a traversal that reaches
  /// it has its remaining voxels marked already or unchangeable. A voxel rays end in may be in it
  /// (its free marks do not count under kSet). The region's frame stays the build's.
  void grow(std::span<const FullyFreeBlock> covered);

  /// Whether block `key` (block::blockOf) has voxels in the box of the last build.
  [[nodiscard]] bool boxHasBlock(std::uint64_t key) const;

  [[nodiscard]] bool contains(const VoxelKey& k) const {
    // Queried in the map's 8^3 block layout: a traversal stays in one cache line for a while.
    const unsigned bx = static_cast<unsigned>(k.x >> block::kShift) - brick_min_[0];
    const unsigned by = static_cast<unsigned>(k.y >> block::kShift) - brick_min_[1];
    const unsigned bz = static_cast<unsigned>(k.z >> block::kShift) - brick_min_[2];
    if (bx >= bricks_n_[0] || by >= bricks_n_[1] || bz >= bricks_n_[2]) return false;
    const std::size_t brick =
        (static_cast<std::size_t>(bz) * bricks_n_[1] + by) * bricks_n_[0] + bx;
    return block::testBit(bricks_[brick], block::indexOf(k));
  }

  /// Whether the region's bricks are indexed as `marks`' blocks (same first block and counts).
  template <class Marks>
  [[nodiscard]] bool sharesFrame(const Marks& marks) const {
    for (int a = 0; a < 3; ++a) {
      if (brick_min_[a] != marks.blockMin(a) || bricks_n_[a] != marks.blockCount(a)) return false;
    }
    return true;
  }
  /// `contains` for a voxel given by its brick (in the shared frame) and index in the brick.
  [[nodiscard]] bool culledAt(std::uint32_t brick, int index) const {
    return block::testBit(bricks_[brick], index);
  }

  /// The region's bits in the shared frame's block layout (culledAt's): block b's at [b].
  [[nodiscard]] const block::BlockMask* frameMasks() const { return bricks_.data(); }

  /// Voxels in the region.
  [[nodiscard]] std::size_t size() const { return size_; }
  /// Voxels of the box the region was built in.
  [[nodiscard]] std::size_t boxVoxels() const { return static_cast<std::size_t>(nx_) * ny_ * nz_; }

 private:
  std::uint64_t* row(unsigned y, unsigned z) {
    return bits_.data() + (static_cast<std::size_t>(z) * ny_ + y) * words_per_row_;
  }
  /// The row the loads write and the sweep reads: loaded_'s in a growable build (the sweep
  /// writes bits_ from it, so grow() loads more and sweeps again without copies), else bits_'s
  /// (swept in place).
  std::uint64_t* loadRow(unsigned y, unsigned z) {
    std::vector<std::uint64_t>& rows = growable_ ? loaded_ : bits_;
    return rows.data() + (static_cast<std::size_t>(z) * ny_ + y) * words_per_row_;
  }
  /// Sets the bits of the box's fully-free voxels (the blocks' layers along z in parallel).
  void loadFullyFree(const OccupancyMap& map);
  /// Sets the bits of these blocks' voxels inside the box (the blocks' layers along z in
  /// parallel; blocks outside the box skipped).
  void loadBlocks(std::span<const FullyFreeBlock> blocks);
  /// Sets the bits of one block's fully-free voxels inside the box.
  void loadBlock(const FullyFreeBlock& b);
  /// Copies the swept rows into bricks_ (the query layout) over the blocks of `frame`; without
  /// `clear` (the same frame), ORs them into the bricks already there.
  void toBricks(const KeyBox& frame, bool clear);
  /// The sweep from O over the loaded rows into bits_, then toBricks(frame_, clear).
  void sweepAndIndex(bool clear = true);
  /// Keeps the run of set bits of `r` that contains bit `x0` (none if it is clear).
  void keepRunThrough(std::uint64_t* r, unsigned x0) const;

  VoxelKey min_{};
  unsigned nx_ = 0, ny_ = 0, nz_ = 0;
  unsigned words_per_row_ = 0;
  std::vector<std::uint64_t> bits_;  // rows along x, for the sweep
  unsigned brick_min_[3] = {0, 0, 0};
  unsigned bricks_n_[3] = {0, 0, 0};
  std::vector<block::BlockMask> bricks_;
  struct Scratch {  // loadFullyFree's arrays, kept between builds
    std::vector<FullyFreeBlock> found, by_layer;
    std::vector<std::size_t> layer_starts;
  };
  Scratch scratch_;
  std::size_t size_ = 0;
  VoxelKey origin_{};
  KeyBox frame_{};
  bool growable_ = false;
  std::vector<std::uint64_t> loaded_;  // the loaded voxels before the sweep (growable builds)
};

/// The box the culling region is built in for a scan: the bounding box of the sensor's voxel
/// and the rays' end voxels (every traversed voxel lies inside it), shrunk around the sensor
/// until it holds at most `max_voxels` voxels.
[[nodiscard]] KeyBox cullingBox(const VoxelKey& origin, const KeyBox& rays_box,
                                std::size_t max_voxels);

}  // namespace densemap
