#include "densemap/map/grid_map.hpp"
#include "densemap/map/cell_update.hpp"

#include <atomic>
#include <bit>
#include <cmath>

#include <type_traits>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "densemap/traversal/ray_traversal.hpp"  // hasWideLanes
#define DENSEMAP_WIDE_APPLY 1
#endif

namespace densemap {

void GridMap::store(BlockNode& node, int index, float log_odds) const {
  node.voxels.log_odds[index] = log_odds;
  if (sensorModel().isFullyFree(log_odds)) {
    block::setBit(node.fully_free, index);
  } else {
    block::clearBit(node.fully_free, index);
  }
}

/// One block's writes in a parallel update (apply, assignBlocks): reads the latest contents; the
/// first change takes the writable node (a copy when a published version still reads the head).
struct GridMap::BlockWriter {
  struct Counts {
    std::size_t updated = 0, changed = 0, newly_known = 0, forgotten = 0;
  };
  GridMap& map;
  BlockEntry& entry;
  Counts& counts;
  CellChanges* out;
  BlockStore::WriteBatch& batch;  // the task's: where the writable node comes from
  const BlockNode* read;
  BlockNode* write = nullptr;

  BlockWriter(GridMap& m, BlockEntry& e, Counts& c, CellChanges* changes, BlockStore::WriteBatch& b)
      : map(m), entry(e), counts(c), out(changes), batch(b), read(BlockStore::latest(e)) {
    static const BlockNode kEmpty{};
    if (read == nullptr) read = &kEmpty;
  }
  [[nodiscard]] bool known(int i) const { return read->voxels.isKnown(i); }
  [[nodiscard]] float value(int i) const { return read->voxels.log_odds[i]; }
  /// Cell i (key) takes `v`: nothing is written for a known cell that already holds it.
  void set(const VoxelKey& key, int i, float v) {
    ++counts.updated;
    const bool was_known = known(i);
    if (was_known && value(i) == v) return;
    change(i, v, was_known, [&] { return key; });
  }
  /// Cell i (key) becomes unknown (a no-op for an unknown cell).
  void forget(const VoxelKey& key, int i) {
    ++counts.updated;
    if (!known(i)) return;
    if (write == nullptr) {
      write = &batch.writable(entry);
      read = write;
    }
    block::clearBit(write->voxels.known, i);
    block::clearBit(write->fully_free, i);
    ++counts.forgotten;
    ++counts.changed;
    if (out != nullptr) out->push_back({key, 0.0F, false});
  }
  /// A UpdateRule::kSet block (no counts): each cell of `free` or `occupied` takes
  /// model.update(value, occupied wins), as set() would, a mask word at a time and the key
  /// computed only for a change list (through forEachCellInBlock and set(), apply took ~14 ns
  /// a cell at 0.1 m; this, ~8).
  /// A cell already at the clamping bound its update moves toward keeps its value, as
  /// OctoMap's updateNode returns early for it ("no change: node already at threshold"; so does
  /// OctreeMap::apply): crossed-only cells that are fully free are dropped a mask word at a time.
  /// The cells of mask word `wd` an update writes: those it reaches, less the fully-free ones
  /// it only crosses (the rule above; the one definition for applySet's three forms).
  [[nodiscard]] std::uint64_t toWrite(std::uint64_t reached, std::uint64_t occupied, int wd) const {
    return reached & ~(read->fully_free[wd] & ~occupied);
  }
  void applySet(std::uint64_t block_key, const ScanUpdate::Block& b, const SensorModel& model) {
#ifdef DENSEMAP_WIDE_APPLY
    if (map.lane_bits_ >= 512 && hasWideLanes()) {
      applySetWide(block_key, b, model);
      return;
    }
    if (map.lane_bits_ >= 256 && hasFourLanes()) {
      applySetEight(block_key, b, model);
      return;
    }
#endif
    const float clamp_max = model.clampMax();
    // The cells updated counted by the processor's popcount where it has one (countBits: the
    // baseline target's std::popcount is a libgcc call a word).
    block::BlockMask reached;
    for (int wd = 0; wd < block::kMaskWords; ++wd) reached[wd] = b.free[wd] | b.occupied[wd];
    counts.updated += block::countBits(reached);
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      const std::uint64_t occupied = b.occupied[wd];
      std::uint64_t todo = toWrite(reached[wd], occupied, wd);
      while (todo != 0) {
        const int bit = std::countr_zero(todo);
        todo &= todo - 1;
        const int i = wd * 64 + bit;
        const bool was_known = ((read->voxels.known[wd] >> bit) & 1U) != 0;
        const float old = was_known ? read->voxels.log_odds[i] : 0.0F;
        const bool hit = ((occupied >> bit) & 1U) != 0;
        if (was_known && hit && old >= clamp_max) continue;
        const float v = model.update(old, hit);
        if (was_known && old == v) continue;
        change(i, v, was_known, [&] { return block::keyOf(block_key, i); });
      }
    }
  }

#ifdef DENSEMAP_WIDE_APPLY
  /// Of the sixteen cells from bit `shift` of mask word `wd`, those of `changed` take `v`'s
  /// lanes (`kn`: those known before), as change() does a cell at a time: the writable node on
  /// the first change, the counts, the change list in cell order, the values and fully-free
  /// bits.
  [[gnu::target("avx512f,avx512vl,avx512dq,avx512bw"), gnu::always_inline]] void writeSixteen(
      std::uint64_t block_key, int wd, int shift, __mmask16 kn, __mmask16 changed, __m512 v,
      __m512 clamp_min) {
    if (write == nullptr) {
      write = &batch.writable(entry);
      read = write;
    }
    const int first = wd * 64 + shift;
    const auto newly = static_cast<__mmask16>(changed & ~kn);
    write->voxels.known[wd] |= static_cast<std::uint64_t>(newly) << shift;
    counts.newly_known += static_cast<std::size_t>(std::popcount(static_cast<unsigned>(newly)));
    counts.changed += static_cast<std::size_t>(std::popcount(static_cast<unsigned>(changed)));
    if (out != nullptr) {
      alignas(64) float values[16];
      _mm512_store_ps(values, v);
      for (unsigned c = changed; c != 0; c &= c - 1) {
        const int k = std::countr_zero(c);
        out->push_back({block::keyOf(block_key, first + k), values[k], true});
      }
    }
    _mm512_mask_storeu_ps(write->voxels.log_odds.data() + first, changed, v);
    const auto free =
        static_cast<__mmask16>(_mm512_cmp_ps_mask(v, clamp_min, _CMP_LE_OQ) & changed);
    const std::uint64_t lanes = static_cast<std::uint64_t>(changed) << shift;
    write->fully_free[wd] =
        (write->fully_free[wd] & ~lanes) | (static_cast<std::uint64_t>(free) << shift);
  }

  /// writeSixteen for eight cells in AVX2 lanes.
  [[gnu::target("avx2,popcnt,bmi"), gnu::always_inline]] void writeEight(std::uint64_t block_key,
                                                                         int wd, int shift,
                                                                         unsigned kn,
                                                                         unsigned changed, __m256 v,
                                                                         __m256 clamp_min) {
    if (write == nullptr) {
      write = &batch.writable(entry);
      read = write;
    }
    const int first = wd * 64 + shift;
    const unsigned newly = changed & ~kn;
    write->voxels.known[wd] |= static_cast<std::uint64_t>(newly) << shift;
    counts.newly_known += static_cast<std::size_t>(__builtin_popcount(newly));
    counts.changed += static_cast<std::size_t>(__builtin_popcount(changed));
    if (out != nullptr) {
      alignas(32) float values[8];
      _mm256_store_ps(values, v);
      for (unsigned c = changed; c != 0; c &= c - 1) {
        const int k = __builtin_ctz(c);
        out->push_back({block::keyOf(block_key, first + k), values[k], true});
      }
    }
    _mm256_maskstore_ps(write->voxels.log_odds.data() + first, lanesOf(changed), v);
    const unsigned free =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(v, clamp_min, _CMP_LE_OQ))) &
        changed;
    const std::uint64_t lanes = static_cast<std::uint64_t>(changed) << shift;
    write->fully_free[wd] =
        (write->fully_free[wd] & ~lanes) | (static_cast<std::uint64_t>(free) << shift);
  }

  /// applySet sixteen cells at a time in AVX-512 lanes: the same float addition and clamps, the
  /// same cells skipped and changed, the changes listed in the same order.
  [[gnu::target("avx512f,avx512vl,avx512dq,avx512bw")]] void applySetWide(
      std::uint64_t block_key, const ScanUpdate::Block& b, const SensorModel& model) {
    const __m512 hit = _mm512_set1_ps(model.hit()), miss = _mm512_set1_ps(model.miss());
    const __m512 clamp_min = _mm512_set1_ps(model.clampMin());
    const __m512 clamp_max = _mm512_set1_ps(model.clampMax());
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      const std::uint64_t occupied = b.occupied[wd];
      std::uint64_t todo = b.free[wd] | occupied;
      counts.updated += static_cast<std::size_t>(std::popcount(todo));
      todo = toWrite(todo, occupied, wd);
      if (todo == 0) continue;
      const std::uint64_t known = read->voxels.known[wd];
      for (int q = 0; q < 4; ++q) {
        const int shift = 16 * q;
        auto cells = static_cast<__mmask16>(todo >> shift);
        if (cells == 0) continue;
        const auto kn = static_cast<__mmask16>(known >> shift);
        const auto hits = static_cast<__mmask16>(occupied >> shift);
        const int first = wd * 64 + shift;
        const __m512 old = _mm512_maskz_loadu_ps(kn, read->voxels.log_odds.data() + first);
        // A known hit cell at or above the upper bound keeps its value (updateNode's return).
        cells &= static_cast<__mmask16>(~_mm512_mask_cmp_ps_mask(static_cast<__mmask16>(kn & hits),
                                                                 old, clamp_max, _CMP_GE_OQ));
        __m512 v = _mm512_add_ps(old, _mm512_mask_blend_ps(hits, miss, hit));
        v = _mm512_mask_blend_ps(_mm512_cmp_ps_mask(v, clamp_min, _CMP_LT_OQ), v, clamp_min);
        v = _mm512_mask_blend_ps(_mm512_cmp_ps_mask(v, clamp_max, _CMP_GT_OQ), v, clamp_max);
        const auto changed =
            static_cast<__mmask16>(cells & ~_mm512_mask_cmp_ps_mask(kn, old, v, _CMP_EQ_OQ));
        if (changed == 0) continue;
        writeSixteen(block_key, wd, shift, kn, changed, v, clamp_min);
      }
    }
  }

  /// The lanes whose bits `m` (8 bits) holds, as all-ones lanes.
  [[gnu::target("avx2"), gnu::always_inline]] static __m256i lanesOf(unsigned m) {
    const __m256i lane_bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    return _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(static_cast<int>(m)), lane_bit),
                              lane_bit);
  }
  /// applySetWide with AVX2: eight cells at a time (no mask registers: lane masks from the
  /// mask bits, masked loads and stores), the same arithmetic, cells and order.
  [[gnu::target("avx2,popcnt,bmi")]] void applySetEight(std::uint64_t block_key,
                                                        const ScanUpdate::Block& b,
                                                        const SensorModel& model) {
    const __m256 hit = _mm256_set1_ps(model.hit()), miss = _mm256_set1_ps(model.miss());
    const __m256 clamp_min = _mm256_set1_ps(model.clampMin());
    const __m256 clamp_max = _mm256_set1_ps(model.clampMax());
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      const std::uint64_t occupied = b.occupied[wd];
      std::uint64_t todo = b.free[wd] | occupied;
      counts.updated += static_cast<std::size_t>(__builtin_popcountll(todo));
      todo = toWrite(todo, occupied, wd);
      if (todo == 0) continue;
      const std::uint64_t known = read->voxels.known[wd];
      for (int q = 0; q < 8; ++q) {
        const int shift = 8 * q;
        unsigned cells = (todo >> shift) & 0xffU;
        if (cells == 0) continue;
        const unsigned kn = (known >> shift) & 0xffU;
        const unsigned hits = (occupied >> shift) & 0xffU;
        const int first = wd * 64 + shift;
        const __m256 old = _mm256_maskload_ps(read->voxels.log_odds.data() + first, lanesOf(kn));
        // A known hit cell at or above the upper bound keeps its value (updateNode's return).
        cells &=
            ~(kn & hits &
              static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(old, clamp_max, _CMP_GE_OQ))));
        __m256 v =
            _mm256_add_ps(old, _mm256_blendv_ps(miss, hit, _mm256_castsi256_ps(lanesOf(hits))));
        v = _mm256_blendv_ps(v, clamp_min, _mm256_cmp_ps(v, clamp_min, _CMP_LT_OQ));
        v = _mm256_blendv_ps(v, clamp_max, _mm256_cmp_ps(v, clamp_max, _CMP_GT_OQ));
        const unsigned changed =
            cells &
            ~(kn & static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(old, v, _CMP_EQ_OQ))));
        if (changed == 0) continue;
        writeEight(block_key, wd, shift, kn, changed, v, clamp_min);
      }
    }
  }
#endif

  /// The cells of `cells` take `values[cell]` as set() gives each (an unchanged known cell is
  /// not written; the changes in cell order), in the widest lanes the map and the processor
  /// allow. False, with nothing written, where there are no lanes or a cell's value is NaN
  /// (forget() is the caller's, cell by cell).
  bool assignInLanes(std::uint64_t block_key, const block::BlockMask& cells, const float* values,
                     float clamp_min) {
#ifdef DENSEMAP_WIDE_APPLY
    if (map.lane_bits_ >= 512 && hasWideLanes())
      return assignWide(block_key, cells, values, clamp_min);
    if (map.lane_bits_ >= 256 && hasFourLanes()) {
      return assignEight(block_key, cells, values, clamp_min);
    }
#endif
    (void)block_key, (void)cells, (void)values, (void)clamp_min;
    return false;
  }

#ifdef DENSEMAP_WIDE_APPLY
  /// assignInLanes sixteen cells at a time in AVX-512 lanes.
  [[gnu::target("avx512f,avx512vl,avx512dq,avx512bw")]] bool assignWide(
      std::uint64_t block_key, const block::BlockMask& cell_mask, const float* values,
      float clamp_min_value) {
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      for (int q = 0; q < 4; ++q) {
        const auto cells = static_cast<__mmask16>(cell_mask[wd] >> (16 * q));
        const __m512 v = _mm512_maskz_loadu_ps(cells, values + wd * 64 + 16 * q);
        if (_mm512_mask_cmp_ps_mask(cells, v, v, _CMP_UNORD_Q) != 0) return false;
      }
    }
    const __m512 clamp_min = _mm512_set1_ps(clamp_min_value);
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      const std::uint64_t todo = cell_mask[wd];
      if (todo == 0) continue;
      counts.updated += static_cast<std::size_t>(std::popcount(todo));
      const std::uint64_t known = read->voxels.known[wd];
      for (int q = 0; q < 4; ++q) {
        const int shift = 16 * q;
        const auto cells = static_cast<__mmask16>(todo >> shift);
        if (cells == 0) continue;
        const auto kn = static_cast<__mmask16>(known >> shift);
        const int first = wd * 64 + shift;
        const __m512 old = _mm512_maskz_loadu_ps(kn, read->voxels.log_odds.data() + first);
        const __m512 v = _mm512_maskz_loadu_ps(cells, values + first);
        const auto changed =
            static_cast<__mmask16>(cells & ~_mm512_mask_cmp_ps_mask(kn, old, v, _CMP_EQ_OQ));
        if (changed == 0) continue;
        writeSixteen(block_key, wd, shift, kn, changed, v, clamp_min);
      }
    }
    return true;
  }

  /// assignInLanes eight cells at a time in AVX2 lanes.
  [[gnu::target("avx2,popcnt,bmi")]] bool assignEight(std::uint64_t block_key,
                                                      const block::BlockMask& cell_mask,
                                                      const float* values, float clamp_min_value) {
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      for (int q = 0; q < 8; ++q) {
        const unsigned cells = (cell_mask[wd] >> (8 * q)) & 0xffU;
        if (cells == 0) continue;
        const __m256 v = _mm256_maskload_ps(values + wd * 64 + 8 * q, lanesOf(cells));
        if ((static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(v, v, _CMP_UNORD_Q))) &
             cells) != 0) {
          return false;
        }
      }
    }
    const __m256 clamp_min = _mm256_set1_ps(clamp_min_value);
    for (int wd = 0; wd < block::kMaskWords; ++wd) {
      const std::uint64_t todo = cell_mask[wd];
      if (todo == 0) continue;
      counts.updated += static_cast<std::size_t>(__builtin_popcountll(todo));
      const std::uint64_t known = read->voxels.known[wd];
      for (int q = 0; q < 8; ++q) {
        const int shift = 8 * q;
        const unsigned cells = (todo >> shift) & 0xffU;
        if (cells == 0) continue;
        const unsigned kn = (known >> shift) & 0xffU;
        const int first = wd * 64 + shift;
        const __m256 old = _mm256_maskload_ps(read->voxels.log_odds.data() + first, lanesOf(kn));
        const __m256 v = _mm256_maskload_ps(values + first, lanesOf(cells));
        const unsigned changed =
            cells &
            ~(kn & static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(old, v, _CMP_EQ_OQ))));
        if (changed == 0) continue;
        writeEight(block_key, wd, shift, kn, changed, v, clamp_min);
      }
    }
    return true;
  }
#endif

 private:
  /// Cell i takes `v` (it had another value, or none): the writable node on the first change.
  template <class KeyOf>
  void change(int i, float v, bool was_known, KeyOf&& key_of) {
    if (write == nullptr) {
      write = &batch.writable(entry);
      read = write;
    }
    if (!was_known) {
      write->voxels.markKnown(i);
      ++counts.newly_known;
    }
    ++counts.changed;
    if (out != nullptr) out->push_back({key_of(), v, true});
    map.store(*write, i, v);
  }
};

template <class WriteBlock, class CellsOf>
ApplyStats GridMap::writeBlocks(std::span<BlockEntry* const> entries, CellChanges* changes,
                                WriteBlock&& write_block, CellsOf&& cells_of) {
  using Counts = BlockWriter::Counts;
  // Each block records its changes in its own slot; slots are concatenated in block order.
  std::vector<CellChanges> block_changes(changes != nullptr ? entries.size() : 0);
  // Chunks of blocks may run at once: each counts its own, added once per chunk.
  std::atomic<std::size_t> updated{0}, changed{0}, newly_known{0}, forgotten{0};
  runner().run(entries.size(), 16, [&](std::size_t begin, std::size_t end) {
    Counts c;
    BlockStore::WriteBatch batch(*store_);
    // Blocks come from all over the map (cache misses): the entry four blocks ahead and the
    // newest node's first lines two ahead are fetched while this one is written.
    const auto prefetchNode = [&](std::size_t k) {
      if (k >= end) return;
      const ChainLink* head = entries[k]->head.load(std::memory_order_relaxed);
      if constexpr (!std::is_same_v<std::decay_t<CellsOf>, std::nullptr_t>) {
        // The lines (16 values each) holding the cells to write, and those of the block's
        // evidence where it has some (a dense map's values are computed from it).
        const block::BlockMask cells = cells_of(k);
        const float* values =
            head != nullptr ? static_cast<const BlockNode*>(head)->voxels.log_odds.data() : nullptr;
        const BlockEvidence* evidence = entries[k]->evidence.get();
        for (int w = 0; w < block::kMaskWords; ++w) {
          for (int q = 0; q < 4; ++q) {
            if (((cells[static_cast<std::size_t>(w)] >> (16 * q)) & 0xffffU) == 0) continue;
            const int line = 64 * w + 16 * q;
            if (values != nullptr) __builtin_prefetch(values + line);
            if (evidence != nullptr) {
              __builtin_prefetch(evidence->alpha.data() + line);
              __builtin_prefetch(evidence->beta.data() + line);
            }
          }
        }
      }
      if (head == nullptr) return;
      const auto* bytes = reinterpret_cast<const char*>(head);
      __builtin_prefetch(bytes);
      __builtin_prefetch(bytes + 64);
    };
    for (std::size_t k = begin; k < std::min(begin + 4, end); ++k) __builtin_prefetch(entries[k]);
    prefetchNode(begin);
    prefetchNode(begin + 1);
    for (std::size_t j = begin; j != end; ++j) {
      if (j + 4 < end) __builtin_prefetch(entries[j + 4]);
      prefetchNode(j + 2);
      BlockWriter w(*this, *entries[j], c, changes != nullptr ? &block_changes[j] : nullptr, batch);
      write_block(j, w);
    }
    updated += c.updated;
    changed += c.changed;
    newly_known += c.newly_known;
    forgotten += c.forgotten;
  });
  const Counts total{.updated = updated.load(),
                     .changed = changed.load(),
                     .newly_known = newly_known.load(),
                     .forgotten = forgotten.load()};
  known_cells_ += total.newly_known;
  known_cells_ -= total.forgotten;
  if (changes != nullptr) {
    for (auto& part : block_changes) changes->insert(changes->end(), part.begin(), part.end());
  }
  return {total.updated, total.changed};
}

ApplyStats GridMap::apply(const ScanUpdate& update, CellChanges* changes) {
  const auto& blocks = update.blocks();
  std::vector<BlockEntry*>& entries = writeEntries(blocks.size());
  // The blocks' entries looked up side by side (reads only: cache misses), then the missing
  // ones created one after the other, in the update's order.
  runner().run(blocks.size(), 256, [&](std::size_t begin, std::size_t end) {
    for (std::size_t j = begin; j != end; ++j) entries[j] = store_->findEntry(blocks[j].first);
  });
  for (std::size_t j = 0; j < blocks.size(); ++j) {
    if (entries[j] == nullptr) entries[j] = &store_->entry(blocks[j].first);
  }
  const SensorModel& model = sensorModel();
  const UpdateRule rule = update.rule();
  const auto cells_of = [&](std::size_t j) {
    block::BlockMask cells;
    for (std::size_t w = 0; w < cells.size(); ++w) {
      cells[w] = blocks[j].second.free[w] | blocks[j].second.occupied[w];
    }
    return cells;
  };
  if (rule == UpdateRule::kSet) {
    return writeBlocks(
        entries, changes,
        [&](std::size_t j, BlockWriter& w) {
          w.applySet(blocks[j].first, blocks[j].second, model);
        },
        cells_of);
  }
  return writeBlocks(
      entries, changes,
      [&](std::size_t j, BlockWriter& w) {
        ScanUpdate::forEachCellInBlock(
            blocks[j].first, blocks[j].second, [&](const VoxelKey& key, const CellHits& hits) {
              const int i = block::indexOf(key);
              w.set(key, i, updatedLogOdds(model, rule, w.known(i) ? w.value(i) : 0.0F, hits));
            });
      },
      cells_of);
}

std::size_t GridMap::clearBox(const VoxelKey& min, const VoxelKey& max, CellChanges* changes) {
  const VoxelKey bmin{static_cast<std::uint16_t>(min.x >> block::kShift),
                      static_cast<std::uint16_t>(min.y >> block::kShift),
                      static_cast<std::uint16_t>(min.z >> block::kShift)};
  const VoxelKey bmax{static_cast<std::uint16_t>(max.x >> block::kShift),
                      static_cast<std::uint16_t>(max.y >> block::kShift),
                      static_cast<std::uint16_t>(max.z >> block::kShift)};
  std::size_t erased = 0;
  auto clearIn = [&](BlockEntry& e) {
    const BlockNode* head = BlockStore::latest(e);
    if (head == nullptr) return;
    const VoxelKey corner = block::keyOf(e.key, 0);
    if ((corner.x >> block::kShift) < bmin.x || (corner.y >> block::kShift) < bmin.y ||
        (corner.z >> block::kShift) < bmin.z || (corner.x >> block::kShift) > bmax.x ||
        (corner.y >> block::kShift) > bmax.y || (corner.z >> block::kShift) > bmax.z) {
      return;
    }
    const int edge = block::kEdge - 1;
    const bool whole = corner.x >= min.x && corner.y >= min.y && corner.z >= min.z &&
                       corner.x + edge <= max.x && corner.y + edge <= max.y &&
                       corner.z + edge <= max.z;
    if (whole) {  // every cell goes: drop the block (its memory returns to the pool)
      erased += dropBlock(e, changes);
      return;
    }
    BlockNode* node = nullptr;
    block::forEachSetBit(head->voxels.known, [&](int i) {
      const VoxelKey k = block::keyOf(e.key, i);
      if (k.x < min.x || k.y < min.y || k.z < min.z || k.x > max.x || k.y > max.y || k.z > max.z) {
        return;
      }
      if (node == nullptr) node = &store_->writable(e);
      block::clearBit(node->voxels.known, i);
      block::clearBit(node->fully_free, i);
      ++erased;
      if (changes != nullptr) changes->push_back({k, 0.0F, false});
    });
    if (node != nullptr && block::countBits(node->voxels.known) == 0) (void)store_->drop(e);
  };
  // Walk the box's blocks when there are fewer of them than blocks in the map.
  const double box_blocks =
      (bmax.x - bmin.x + 1.0) * (bmax.y - bmin.y + 1.0) * (bmax.z - bmin.z + 1.0);
  if (box_blocks < static_cast<double>(store_->entryCount())) {
    for (unsigned z = bmin.z; z <= bmax.z; ++z) {
      for (unsigned y = bmin.y; y <= bmax.y; ++y) {
        for (unsigned x = bmin.x; x <= bmax.x; ++x) {
          const VoxelKey corner{static_cast<std::uint16_t>(x << block::kShift),
                                static_cast<std::uint16_t>(y << block::kShift),
                                static_cast<std::uint16_t>(z << block::kShift)};
          const std::uint64_t key = block::blockOf(corner);
          if (store_->latest(key) != nullptr) clearIn(store_->entry(key));
        }
      }
    }
  } else {
    store_->forEachEntryWriter([&](BlockEntry& e) { clearIn(e); });
  }
  known_cells_ -= erased;
  return erased;
}

std::size_t GridMap::dropBlock(BlockEntry& e, CellChanges* changes) {
  const BlockNode* head = BlockStore::latest(e);
  if (head == nullptr) return 0;
  const std::size_t cells = block::countBits(head->voxels.known);
  if (changes != nullptr) {
    block::forEachSetBit(head->voxels.known, [&](int i) {
      changes->push_back({block::keyOf(e.key, i), 0.0F, false});
    });
  }
  (void)store_->drop(e);
  return cells;
}

EvictStats GridMap::evictBlocks(const std::function<bool(const Point3f&)>& keep,
                                CellChanges* changes) {
  EvictStats stats;
  const auto keepsAll = [&](const block::BlockBox& box) {
    for (int corner = 0; corner < 8; ++corner) {
      std::uint64_t key = 0;
      for (int a = 0; a < 3; ++a) {
        key |= std::uint64_t{(corner >> a & 1) != 0 ? box.max[a] : box.min[a]} << (13 * a);
      }
      if (!keep(block::centreOf(grid(), key))) return false;
    }
    return true;
  };
  store_->forEachRegionWriter([&](const block::BlockBox& box, auto&& for_each_entry) {
    if (keepsAll(box)) return;
    for_each_entry([&](BlockEntry* e) {
      if (BlockStore::latest(*e) == nullptr) return;
      if (keep(block::centreOf(grid(), e->key))) return;
      const std::size_t cells = dropBlock(*e, changes);
      known_cells_ -= cells;
      stats.cells += cells;
      ++stats.blocks;
    });
  });
  return stats;
}

std::optional<float> GridMap::logOdds(const VoxelKey& key) const {
  const BlockNode* n = store_->latest(block::blockOf(key));
  if (n == nullptr) return std::nullopt;
  const int i = block::indexOf(key);
  if (!n->voxels.isKnown(i)) return std::nullopt;
  return n->voxels.log_odds[i];
}

void GridMap::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  store_->forEachEntryWriter([&](const BlockEntry& e) {
    const BlockNode* n = BlockStore::latest(e);
    if (n == nullptr) return;
    block::forEachSetBit(n->voxels.known,
                         [&](int i) { f(block::keyOf(e.key, i), n->voxels.log_odds[i]); });
  });
}

void GridMap::appendFullyFreeBlocks(const block::BlockBox& box,
                                    std::vector<FullyFreeBlock>& out) const {
  store_->forEachEntryIn(box, [&](const BlockEntry& e) {
    const BlockNode* n = BlockStore::latest(e);
    if (n != nullptr && block::anyBit(n->fully_free)) {
      out.push_back({e.key, n->fully_free});
    }
  });
}

void GridMap::setLogOdds(const VoxelKey& key, float log_odds) {
  BlockNode& node = store_->writable(store_->entry(block::blockOf(key)));
  const int i = block::indexOf(key);
  if (!node.voxels.isKnown(i)) {
    node.voxels.markKnown(i);
    ++known_cells_;
  }
  store(node, i, log_odds);
}

void GridMap::erase(const VoxelKey& key) {
  const std::uint64_t bk = block::blockOf(key);
  const BlockNode* latest = store_->latest(bk);
  const int i = block::indexOf(key);
  if (latest == nullptr || !latest->voxels.isKnown(i)) return;
  BlockNode& node = store_->writable(store_->entry(bk));
  block::clearBit(node.voxels.known, i);
  block::clearBit(node.fully_free, i);
  --known_cells_;
}

void GridMap::applyChanges(const CellChanges& changes) {
  for (const CellChange& c : changes) {
    if (c.known) {
      setLogOdds(c.key, c.log_odds);
    } else {
      erase(c.key);
    }
  }
}

ApplyStats GridMap::assignBlocks(std::span<const BlockCells> blocks, const BlockValues& values_of,
                                 CellChanges* changes) {
  std::vector<BlockEntry*>& entries = writeEntries(blocks.size());
  for (std::size_t j = 0; j < blocks.size(); ++j) entries[j] = &store_->entry(blocks[j].key);
  std::atomic<bool> forgot{false};
  const float clamp_min = sensorModel().clampMin();
  const ApplyStats stats = writeBlocks(
      entries, changes,
      [&](std::size_t j, BlockWriter& w) {
        std::array<float, block::kVoxels> values;  // only the mask's cells are read
        const BlockCells& b = blocks[j];
        values_of(b.key, b.cells, values);
        if (w.assignInLanes(b.key, b.cells, values.data(), clamp_min)) return;
        block::forEachSetBit(b.cells, [&](int i) {
          if (std::isnan(values[i])) {
            w.forget(block::keyOf(b.key, i), i);
            forgot.store(true, std::memory_order_relaxed);
          } else {
            w.set(block::keyOf(b.key, i), i, values[i]);
          }
        });
      },
      [&](std::size_t j) { return blocks[j].cells; });
  if (forgot.load()) {  // blocks left with no known cell go, as clearBox's do
    for (BlockEntry* e : entries) {
      const BlockNode* n = BlockStore::latest(*e);
      if (n != nullptr && !block::anyBit(n->voxels.known)) (void)store_->drop(*e);
    }
  }
  return stats;
}

void GridMap::clear() {
  if (!store_->versioned()) {  // nobody reads older versions: drop everything at once
    store_->clearUnversioned();
    known_cells_ = 0;
    return;
  }
  // Readers keep their versions: drop every block from the next one.
  store_->forEachEntryWriter([&](BlockEntry& e) { (void)store_->drop(e); });
  known_cells_ = 0;
}

}  // namespace densemap
