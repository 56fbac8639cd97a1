#pragma once

// DenseMarks' step-by-step walkers: Cursor (a walk's voxel as a value a loop keeps in registers)
// and StepMarker (one ray's voxels marked as its walk follows them). Included by dense_marks.hpp.
#include "densemap/traversal/dense_marks.hpp"

namespace densemap {

/// A walk's voxel in the box as a value, for a walk's loop to keep in registers (a
/// StepMarker lives in memory, and its loop reloaded and stored its state at every step): the
/// voxel's block and its index in the block followed step by step as StepMarker::move does
/// (a block border every 8 steps, counted down per axis), the first-touch bookkeeping once per
/// block entered. Only for walks whose voxels are all in the box — a walk between two voxels
/// of the box (it moves monotonically) — so there is no box test. Made by
/// StepMarker::cursorFor; its last marks and touched count go back by StepMarker::resume.
class DenseMarks::Cursor {
 public:
  /// The walk stepped along axis A.
  template <int A>
  void move() {
    index_ = static_cast<unsigned>(static_cast<int>(index_) + index_step_[A]);
    if (--left_[A] == 0) {  // into the next block along A: the coordinate wraps
      left_[A] = block::kEdge;
      index_ = static_cast<unsigned>(static_cast<int>(index_) - block::kEdge * index_step_[A]);
      block_ = static_cast<std::uint32_t>(static_cast<std::int32_t>(block_) + block_step_[A]);
      touchIn(block_, seen_, touched_, count_);
      load();
    } else if constexpr (A == 2) {
      load();  // a z step changes the mask word (a word holds one layer of the block)
    }
  }
  /// Marks the walk's voxel free.
  void mark() { bits_ |= std::uint64_t{1} << (index_ & 63U); }
  /// StepMarker::markUnlessCulled.
  bool markUnlessCulled() {
    const std::uint64_t bit = std::uint64_t{1} << (index_ & 63U);
    if ((culled_bits_ & bit) != 0) return false;
    bits_ |= bit;
    return true;
  }
  /// Writes the marks not yet in the mask array (before the cursor is dropped).
  void flush() const { *word_ |= bits_; }

 private:
  friend class DenseMarks;
  /// The voxel's mask word changed: the marks gathered for the last one are ORed into it
  /// (one store per word, not a load and store per voxel, each waiting on the one before),
  /// and the region's word for the new one is read.
  void load() {
    *word_ |= bits_;
    bits_ = 0;
    const unsigned w = index_ >> 6;
    word_ = &masks_[block_][w];
    culled_bits_ = culled_ != nullptr ? culled_[block_][w] : 0;
  }
  block::BlockMask* masks_ = nullptr;
  const block::BlockMask* culled_ = nullptr;
  std::uint8_t* seen_ = nullptr;
  std::uint32_t* touched_ = nullptr;
  std::uint64_t* word_ = nullptr;  // the voxel's mask word
  std::uint64_t bits_ = 0;         // marks for *word_ not yet written
  std::uint64_t culled_bits_ = 0;  // the region's bits of the voxel's word
  std::uint32_t count_ = 0;
  std::uint32_t block_ = 0;
  unsigned index_ = 0;
  int left_[3] = {0, 0, 0};        // steps along the axis until the next block border
  int index_step_[3] = {0, 0, 0};  // a step's change of the index
  std::int32_t block_step_[3] = {0, 0, 0};
};

/// Marks one ray's voxels as markFree does, following the ray's walk step by step: the
/// voxel's block in the box and its index in the block are updated from the axis stepped and
/// its new key (a block border every 8 steps), not computed from the key; the box test and
/// the first-touch bookkeeping run once per block the walk enters; the hot state (arrays,
/// box, touched count) is in locals until finish() (markFree's members are reloaded and stored
/// around every mark: a mask word's store may alias a size_t member). With a culling region
/// sharing this box's frame (`culled`: its bits in the box's block layout, block b's at
/// [b]), markUnlessCulled tests the region's bit one word address from the mark.
/// A walk moves monotonically (each axis one way), so once it leaves the box it stays out:
/// its marks then go to `outside` by key. One at a time; not to outlive the scan's reset.
class DenseMarks::StepMarker {
 public:
  StepMarker(DenseMarks& marks, ScanUpdate& outside, const block::BlockMask* culled = nullptr)
      : marks_(marks),
        outside_(outside),
        culled_(culled),
        masks_(marks.masks_.data()),
        seen_(marks.seen_.data()),
        touched_(marks.touched_.data()),
        count_(static_cast<std::uint32_t>(marks.touched_count_)),
        n_{marks.n_[0], marks.n_[1], marks.n_[2]} {}
  /// Writes the touched count back (the marks are in place already).
  void finish() { marks_.touched_count_ = count_; }

  /// Starts a walk in voxel `k` (not marked here: mark() marks the walk's voxel) that moves
  /// by `delta[a]` (-1, 0 or 1) along axis a.
  void begin(const VoxelKey& k, const int (&delta)[3]) {
    key_ = k;
    const std::int32_t stride[3] = {1, static_cast<std::int32_t>(n_[0]),
                                    static_cast<std::int32_t>(n_[0] * n_[1])};
    for (int a = 0; a < 3; ++a) {
      block_at_[a] = static_cast<unsigned>(k[a] >> block::kShift) - marks_.min_[a];
      block_delta_[a] = delta[a];
      block_step_[a] = delta[a] * stride[a];
      wrap_[a] = delta[a] < 0 ? block::kEdge - 1 : 0;
    }
    block_ = blockIndexIn(k, marks_.min_, n_);
    out_ = block_ == kOutside;
    index_ = static_cast<unsigned>(block::indexOf(k));
    if (!out_) enter();
  }
  /// The walk stepped along axis A to key coordinate `coord`.
  template <int A>
  void move(int coord) {
    constexpr unsigned kField = (block::kEdge - 1U) << (block::kShift * A);
    key_[A] = static_cast<std::uint16_t>(coord);
    const unsigned c = static_cast<unsigned>(coord) & (block::kEdge - 1U);
    index_ = (index_ & ~kField) | (c << (block::kShift * A));
    if (c == wrap_[A]) {  // a new block
      block_at_[A] += static_cast<unsigned>(block_delta_[A]);
      block_ = static_cast<std::uint32_t>(static_cast<std::int32_t>(block_) + block_step_[A]);
      if (block_at_[A] >= n_[A]) {
        out_ = true;
      } else if (!out_) {
        enter();
      }
    }
  }
  /// A cursor (same marks, same region) for a walk from voxel `first` — entered here, not
  /// marked — moving by `delta[a]` (-1, 0 or 1) along axis a to voxel `last`, when both are in
  /// the box; else none (the walk may leave the box: then begin() and steps here). In place of
  /// begin().
  [[nodiscard]] std::optional<Cursor> cursorFor(const VoxelKey& first, const int (&delta)[3],
                                                const VoxelKey& last) {
    const std::uint32_t block = blockIndexIn(first, marks_.min_, n_);
    if (block == kOutside || blockIndexIn(last, marks_.min_, n_) == kOutside) {
      return std::nullopt;
    }
    Cursor c;
    c.masks_ = masks_;
    c.culled_ = culled_;
    c.seen_ = seen_;
    c.touched_ = touched_;
    c.block_ = block;
    c.index_ = static_cast<unsigned>(block::indexOf(first));
    // Per axis (written out: a loop over VoxelKey's operator[] took ~175 instructions a ray).
    constexpr int m = block::kEdge - 1;
    const auto left = [](int d, int in_block) {
      return d > 0 ? block::kEdge - in_block : in_block + 1;
    };
    c.left_[0] = left(delta[0], first.x & m);
    c.left_[1] = left(delta[1], first.y & m);
    c.left_[2] = left(delta[2], first.z & m);
    c.index_step_[0] = delta[0];
    c.index_step_[1] = delta[1] * block::kEdge;
    c.index_step_[2] = delta[2] * (block::kEdge * block::kEdge);
    c.block_step_[0] = delta[0];
    c.block_step_[1] = delta[1] * static_cast<std::int32_t>(n_[0]);
    c.block_step_[2] = delta[2] * static_cast<std::int32_t>(n_[0] * n_[1]);
    touchIn(block, seen_, touched_, count_);  // entered, as enter()
    c.count_ = count_;
    const unsigned w = c.index_ >> 6;
    c.word_ = &masks_[block][w];
    c.culled_bits_ = culled_ != nullptr ? culled_[block][w] : 0;
    return c;
  }
  /// Takes back a cursor: writes its last marks and its touched count; the walk ends or goes
  /// on by keys (the marker's own voxel is not the cursor's).
  void resume(const Cursor& c) {
    c.flush();
    count_ = c.count_;
  }

  /// Marks the walk's voxel free.
  void mark() {
    if (out_) {
      outside_.markFree(key_);
      return;
    }
    masks_[block_][index_ >> 6] |= std::uint64_t{1} << (index_ & 63U);
  }
  /// Marks the walk's voxel free unless the region (`culled`) holds it; returns whether it
  /// marked. For walks inside the box (a traversal between two voxels of the box).
  bool markUnlessCulled() {
    const unsigned word = index_ >> 6;
    const std::uint64_t bit = std::uint64_t{1} << (index_ & 63U);
    if ((culled_[block_][word] & bit) != 0) return false;
    masks_[block_][word] |= bit;
    return true;
  }

 private:
  void enter() {  // the walk entered block_: first touch of the scan?
    touchIn(block_, seen_, touched_, count_);
  }
  DenseMarks& marks_;
  ScanUpdate& outside_;
  const block::BlockMask* culled_;
  block::BlockMask* masks_;
  std::uint8_t* seen_;
  std::uint32_t* touched_;
  // 32 bits, not size_t: a mask word's store (uint64_t) cannot alias it, so it stays in a
  // register across marks.
  std::uint32_t count_;
  unsigned n_[3];
  unsigned block_at_[3] = {0, 0, 0};  // the voxel's block in the box, per axis
  std::int32_t block_delta_[3] = {0, 0, 0};
  std::int32_t block_step_[3] = {0, 0, 0};
  unsigned wrap_[3] = {0, 0, 0};
  std::uint32_t block_ = 0;
  unsigned index_ = 0;
  VoxelKey key_{};
  bool out_ = false;
};

}  // namespace densemap
