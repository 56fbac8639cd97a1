#include "densemap/planner/distance_field.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <mutex>
#include <string>
#include <utility>

#include "densemap/map/sensor_model.hpp"

namespace densemap {

namespace {

constexpr int kMaxBlockCoord = 0x1fff;

[[nodiscard]] std::uint64_t packBlock(int bx, int by, int bz) {
  return static_cast<std::uint64_t>(bx) | (static_cast<std::uint64_t>(by) << 13) |
         (static_cast<std::uint64_t>(bz) << 26);
}

/// The occupied cells of a map block (known, log-odds above the threshold).
[[nodiscard]] block::BlockMask occupiedOf(const VoxelBlock* b) {
  block::BlockMask m{};
  if (b == nullptr) return m;
  for (int w = 0; w < block::kMaskWords; ++w) {
    std::uint64_t bits = 0;
    for (int i = 0; i < 64; ++i) {
      bits |= static_cast<std::uint64_t>(b->log_odds[w * 64 + i] > 0.0F) << i;
    }
    m[w] = bits & b->known[w];
  }
  return m;
}

/// floor(a / b) for b > 0.
[[nodiscard]] int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/// The 8 bits of one x-row (y, z within the block) of a block mask.
[[nodiscard]] std::uint64_t rowByte(const block::BlockMask& m, int y, int z) {
  return (m[z & 7] >> ((y & 7) * 8)) & 0xffU;
}

}  // namespace

Expected<DistanceField> DistanceField::create(double resolution_m,
                                              const DistanceFieldOptions& options) {
  if (!(std::isfinite(resolution_m) && resolution_m > 0)) {
    return makeError("distance field: resolution must be finite and > 0");
  }
  const double cells = options.max_distance_m / resolution_m;
  if (!(std::isfinite(options.max_distance_m) && options.max_distance_m > 0)) {
    return makeError("max_distance must be finite and > 0 (metres), got " +
                     std::to_string(options.max_distance_m));
  }
  if (cells < 1.0 || cells > kMaxRadiusCells) {
    return makeError(
        "max_distance must be 1 to " + std::to_string(kMaxRadiusCells) + " cells (" +
        std::to_string(resolution_m) + " .. " + std::to_string(kMaxRadiusCells * resolution_m) +
        " m at this resolution), got " + std::to_string(options.max_distance_m) + " m");
  }
  return DistanceField(resolution_m, options);
}

DistanceField::DistanceField(double resolution_m, const DistanceFieldOptions& options)
    : resolution_m_(resolution_m), options_(options) {
  const double cells = options.max_distance_m / resolution_m;
  // The largest integer squared distance within the maximum (a hair of slack so that 2 m at
  // 0.2 m is 100 cells^2, not 99 by rounding).
  radius2_ = static_cast<std::uint32_t>(std::floor(cells * cells * (1 + 1e-9)));
  radius_ = static_cast<int>(std::floor(std::sqrt(static_cast<double>(radius2_))));
  narrow_ = radius2_ < std::numeric_limits<std::uint8_t>::max();
  for (int dz = -radius_; dz <= radius_; ++dz) {
    for (int dy = -radius_; dy <= radius_; ++dy) {
      const auto h = static_cast<std::uint32_t>(dy * dy + dz * dz);
      if (h > radius2_) continue;
      const int ext = static_cast<int>(std::floor(std::sqrt(static_cast<double>(radius2_ - h))));
      rows_.push_back({dy, dz, h, ext});
    }
  }
  for (std::uint32_t h = 0; h <= radius2_; ++h) {
    ext_.push_back(static_cast<int>(std::floor(std::sqrt(static_cast<double>(radius2_ - h)))));
  }
  std::vector<std::vector<std::array<std::int8_t, 3>>> shells(radius2_ + 1);
  for (int dz = -radius_; dz <= radius_; ++dz) {
    for (int dy = -radius_; dy <= radius_; ++dy) {
      for (int dx = -radius_; dx <= radius_; ++dx) {
        const auto d2 = static_cast<std::uint32_t>(dx * dx + dy * dy + dz * dz);
        if (d2 <= radius2_) {
          shells[d2].push_back({static_cast<std::int8_t>(dx), static_cast<std::int8_t>(dy),
                                static_cast<std::int8_t>(dz)});
        }
      }
    }
  }
  for (const auto& shell : shells) {
    shell_begin_.push_back(static_cast<std::uint32_t>(shell_offsets_.size()));
    shell_offsets_.insert(shell_offsets_.end(), shell.begin(), shell.end());
  }
  shell_begin_.push_back(static_cast<std::uint32_t>(shell_offsets_.size()));
  std::stable_sort(rows_.begin(), rows_.end(),
                   [](const BallRow& a, const BallRow& b) { return a.h < b.h; });
}

void DistanceField::clear() {
  narrow_blocks_.clear();
  wide_blocks_.clear();
  sources_.clear();
}

std::size_t DistanceField::memoryBytes() const {
  // The field's blocks, and the maps' slot arrays.
  const std::size_t block_bytes =
      narrow_ ? sizeof(Block<std::uint8_t>) : sizeof(Block<std::uint16_t>);
  return withBlocks([&](const auto& b) { return b.size() * block_bytes + b.bytes(); }) +
         sources_.bytes();
}

std::uint16_t DistanceField::distanceSquared(const VoxelKey& cell) const {
  return withBlocks([&](const auto& blocks) -> std::uint16_t {
    const auto* b = blocks.get(block::blockOf(cell));
    if (b == nullptr) return kFar;
    const auto v = (*b)->d2[block::indexOf(cell)];
    return isFar(v) ? kFar : static_cast<std::uint16_t>(v);
  });
}

std::optional<VoxelKey> DistanceField::nearestOccupied(const VoxelKey& cell) const {
  const std::uint16_t d2 = distanceSquared(cell);
  if (d2 == kFar) return std::nullopt;
  // The distance is known: the nearest occupied cell is one of the lattice points of that
  // sphere; the first occupied one is the answer. The candidates meet a few blocks again and
  // again: each is looked up once (a small direct-mapped cache of the occupied masks).
  struct Slot {
    std::uint64_t key = ~std::uint64_t{0};
    const block::BlockMask* mask = nullptr;
  };
  std::array<Slot, 16> cache{};
  const CellCoord c = CellCoord::of(cell);
  for (std::uint32_t i = shell_begin_[d2]; i < shell_begin_[d2 + 1U]; ++i) {
    const auto& o = shell_offsets_[i];
    const CellCoord n{c.x + o[0], c.y + o[1], c.z + o[2]};
    if (!n.inRange()) continue;
    const std::uint64_t key = packBlock(n.x >> 3, n.y >> 3, n.z >> 3);
    Slot& slot = cache[(key ^ (key >> 13) ^ (key >> 26)) & 15];
    if (slot.key != key) {
      slot = {key, sources_.get(key)};
    }
    if (slot.mask != nullptr &&
        block::testBit(*slot.mask, (n.x & 7) | ((n.y & 7) << 3) | ((n.z & 7) << 6))) {
      return n.key();
    }
  }
  return std::nullopt;  // not reached while the field is current
}

DistanceUpdateStats DistanceField::update(const MapView& view,
                                          std::span<const std::uint64_t> blocks,
                                          const ChunkRunner& runner) {
  std::vector<CellCoord> added;
  std::vector<CellCoord> removed;
  for (const std::uint64_t key : blocks) {
    const block::BlockMask now = occupiedOf(view.block(key));
    const block::BlockMask* had = sources_.get(key);
    const block::BlockMask before = had == nullptr ? block::BlockMask{} : *had;
    block::BlockMask plus{};
    block::BlockMask minus{};
    for (int w = 0; w < block::kMaskWords; ++w) {
      plus[w] = now[w] & ~before[w];
      minus[w] = before[w] & ~now[w];
    }
    block::forEachSetBit(plus,
                         [&](int i) { added.push_back(CellCoord::of(block::keyOf(key, i))); });
    block::forEachSetBit(minus,
                         [&](int i) { removed.push_back(CellCoord::of(block::keyOf(key, i))); });
    if (block::anyBit(now)) {
      sources_[key] = now;
    } else if (had != nullptr) {
      sources_.erase(key);
    }
  }
  DistanceUpdateStats stats;
  apply(added, removed, stats, runner);
  stats.field_blocks = this->blocks();
  return stats;
}

DistanceUpdateStats DistanceField::rebuild(const MapView& view, const ChunkRunner& runner) {
  clear();
  std::vector<std::uint64_t> keys;
  view.forEachBlock([&](std::uint64_t key, const VoxelBlock&) { keys.push_back(key); });
  return update(view, keys, runner);
}

namespace {

/// The occupied-cell masks of the (at most 2 x 2 x 2) blocks within 2 cells of a cell, looked
/// up once each.
class NearMasks {
 public:
  using Sources = FlatMap<block::BlockMask>;
  NearMasks(const Sources& sources, const CellCoord& c) {
    base_ = {std::max(c.x - 2, 0) >> 3, std::max(c.y - 2, 0) >> 3, std::max(c.z - 2, 0) >> 3};
    for (int k = 0; k < 8; ++k) {
      const int bx = base_[0] + (k & 1), by = base_[1] + ((k >> 1) & 1),
                bz = base_[2] + ((k >> 2) & 1);
      if (bx > kMaxBlockCoord || by > kMaxBlockCoord || bz > kMaxBlockCoord) continue;
      masks_[static_cast<std::size_t>(k)] = sources.get(packBlock(bx, by, bz));
    }
  }
  /// Whether cell (x, y, z), within 2 cells of the cell, is occupied.
  [[nodiscard]] bool occupied(int x, int y, int z) const {
    if (x < 0 || x > 0xffff || y < 0 || y > 0xffff || z < 0 || z > 0xffff) return false;
    const int k =
        ((x >> 3) - base_[0]) | (((y >> 3) - base_[1]) << 1) | (((z >> 3) - base_[2]) << 2);
    const block::BlockMask* m = masks_[static_cast<std::size_t>(k)];
    return m != nullptr && block::testBit(*m, (x & 7) | ((y & 7) << 3) | ((z & 7) << 6));
  }

 private:
  std::array<int, 3> base_{};
  std::array<const block::BlockMask*, 8> masks_{};
};

}  // namespace

void DistanceField::segmentsOf(const CellCoord& s, bool add, std::vector<Segment>& out,
                               std::vector<std::array<int, 4>>& near) const {
  // The occupied cells (as they are now) within 2 cells of s, nearest first: a cell strictly
  // nearer one of them than s cannot take its value from s, so s's ball is visited only
  // where none is (2 v.n <= |n|^2 for the cell's offset v and every near offset n).
  near.clear();
  const NearMasks masks(sources_, s);
  for (int dz = -2; dz <= 2; ++dz) {
    for (int dy = -2; dy <= 2; ++dy) {
      for (int dx = -2; dx <= 2; ++dx) {
        if ((dx != 0 || dy != 0 || dz != 0) && masks.occupied(s.x + dx, s.y + dy, s.z + dz)) {
          near.push_back({dx, dy, dz, dx * dx + dy * dy + dz * dz});
        }
      }
    }
  }
  std::sort(near.begin(), near.end(), [](const auto& u, const auto& v) { return u[3] < v[3]; });

  // Near cells straight along y or z bound the rows at once (a wall's or floor's cell keeps
  // only the rows along its normal).
  int dy_lo = -radius_, dy_hi = radius_, dz_lo = -radius_, dz_hi = radius_;
  for (const auto& n : near) {
    if (n[0] != 0 || (n[1] != 0 && n[2] != 0)) continue;
    const int a = n[1] != 0 ? n[1] : n[2];
    int& lo = n[1] != 0 ? dy_lo : dz_lo;
    int& hi = n[1] != 0 ? dy_hi : dz_hi;
    if (a > 0) {
      hi = std::min(hi, floorDiv(n[3], 2 * a));
    } else {
      lo = std::max(lo, -floorDiv(n[3], -2 * a));
    }
  }
  for (int dz = dz_lo; dz <= dz_hi; ++dz) {
    const int z = s.z + dz;
    if (z < 0 || z > 0xffff) continue;
    for (int dy = dy_lo; dy <= dy_hi; ++dy) {
      const int y = s.y + dy;
      const auto h = static_cast<std::uint32_t>(dy * dy + dz * dz);
      if (h > radius2_ || y < 0 || y > 0xffff) continue;
      int lo = -ext_[h], hi = ext_[h];
      for (const auto& n : near) {
        const int k = n[3] - 2 * (dy * n[1] + dz * n[2]);  // keep 2 dx n.x <= k
        if (n[0] == 0) {
          if (k < 0) lo = hi + 1;
        } else if (n[0] > 0) {  // floor(k / (2 n.x)), n.x in {1, 2}: a shift
          hi = std::min(hi, k >> n[0]);
        } else {
          lo = std::max(lo, -(k >> -n[0]));
        }
        if (lo > hi) break;
      }
      const int xa = std::max(s.x + lo, 0), xb = std::min(s.x + hi, 0xffff);
      if (xa > xb) continue;
      const auto cell_row = static_cast<std::uint8_t>((y & 7) | ((z & 7) << 3));
      for (int bx = xa >> 3; bx <= xb >> 3; ++bx) {
        const int ox = bx * 8;
        out.push_back({packBlock(bx, y >> 3, z >> 3), static_cast<std::uint16_t>(h),
                       static_cast<std::int16_t>(s.x - ox), cell_row,
                       static_cast<std::uint8_t>(std::max(xa, ox) - ox),
                       static_cast<std::uint8_t>(std::min(xb, ox + 7) - ox), add});
      }
    }
  }
}

void DistanceField::apply(const std::vector<CellCoord>& added,
                          const std::vector<CellCoord>& removed, DistanceUpdateStats& stats,
                          const ChunkRunner& runner) {
  stats.added = added.size();
  stats.removed = removed.size();
  if (added.empty() && removed.empty()) return;
  // Each changed cell's ball as row segments, per block of the field (chunks of changed cells
  // on the runner, each into its own list).
  const std::size_t n = added.size() + removed.size();
  std::vector<std::vector<Segment>> parts;
  std::mutex parts_mutex;
  runner.run(n, 64, [&](std::size_t begin, std::size_t end) {
    std::vector<std::array<int, 4>> near;
    std::vector<Segment> out;
    for (std::size_t i = begin; i != end; ++i) {
      const bool add = i < added.size();
      segmentsOf(add ? added[i] : removed[i - added.size()], add, out, near);
    }
    const std::lock_guard lock(parts_mutex);
    parts.push_back(std::move(out));
  });
  // The segments grouped by block (a counting sort: each block's place found once per
  // segment in a hash map of the blocks met, then each segment put in its block's run).
  FlatMap<std::uint32_t> group_of;  // block -> its group + 1
  std::vector<std::uint64_t> group_keys;
  std::vector<std::size_t> group_start;  // counts, then where each group starts
  std::vector<std::uint32_t> groups;     // each segment's group, in the parts' order
  for (const auto& p : parts) {
    for (const Segment& g : p) {
      std::uint32_t& slot = group_of[g.block];
      if (slot == 0) {
        group_keys.push_back(g.block);
        group_start.push_back(0);
        slot = static_cast<std::uint32_t>(group_keys.size());
      }
      groups.push_back(slot - 1);
      ++group_start[slot - 1];
    }
  }
  std::size_t total = 0;
  for (std::size_t& start : group_start) total += std::exchange(start, total);
  std::vector<Segment> segments(total);
  {
    std::vector<std::size_t> next = group_start;
    std::size_t k = 0;
    for (const auto& p : parts) {
      for (const Segment& g : p) segments[next[groups[k++]]++] = g;
    }
  }
  group_start.push_back(total);

  withBlocks([&](auto& blocks) {
    applySegments(blocks, segments, group_keys, group_start, stats, runner);
  });
}

template <class T>
void DistanceField::applySegments(Blocks<T>& blocks, std::vector<Segment>& segments,
                                  const std::vector<std::uint64_t>& group_keys,
                                  const std::vector<std::size_t>& group_start,
                                  DistanceUpdateStats& stats, const ChunkRunner& runner) {
  // Blocks first (serially: the table changes), then each block's segments on the runner: a
  // block's task writes only that block and reads the occupied cells, which stay as they are.
  std::vector<Target<T>> targets;
  for (std::size_t gi = 0; gi < group_keys.size(); ++gi) {
    const std::size_t i = group_start[gi], j = group_start[gi + 1];
    const bool any_add = std::any_of(segments.begin() + static_cast<std::ptrdiff_t>(i),
                                     segments.begin() + static_cast<std::ptrdiff_t>(j),
                                     [](const Segment& g) { return g.add; });
    const std::uint64_t key = group_keys[gi];
    Block<T>* b = nullptr;
    if (auto* found = blocks.get(key); found != nullptr) {
      b = found->get();
    } else if (any_add) {
      b = (blocks[key] = std::make_unique<Block<T>>()).get();
    }
    // No block and nothing added: no finite cell here, no removed cell was anyone's nearest.
    if (b != nullptr) targets.push_back({key, b, &segments[i], j - i, {}, false});
  }
  runner.run(targets.size(), 16, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t != end; ++t) stampBlock(targets[t]);
  });
  std::size_t recomputed = 0;
  runner.run(targets.size(), 4, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint64_t> window;
    std::size_t count = 0;
    for (std::size_t t = begin; t != end; ++t) {
      if (targets[t].any_marked) count += recomputeBlock(targets[t], window);
    }
    std::atomic_ref<std::size_t>(recomputed).fetch_add(count, std::memory_order_relaxed);
  });
  stats.recomputed = recomputed;
  for (const Target<T>& t : targets) {
    if (std::all_of(t.block->d2.begin(), t.block->d2.end(), [](T v) { return isFar(v); })) {
      blocks.erase(t.key);
    }
  }
}

template <class T>
void DistanceField::stampBlock(Target<T>& t) const {
  // Segments lie within the ball: every value written is at most radius2_, below the far mark.
  const auto limit = static_cast<std::uint16_t>(radius2_);
  Block<T>& b = *t.block;
  // Additions first: a cell an added cell brought nearer than a removed one holds its exact
  // value already (every remaining occupied cell is at least as far as the removed one was)
  // and is not marked; a cell still at a removed cell's distance is marked and searched anew.
  for (int pass = 0; pass < 2; ++pass) {
    const bool adding = pass == 0;
    for (std::size_t k = 0; k < t.count; ++k) {
      const Segment& g = t.segments[k];
      if (g.add != adding) continue;
      T* row = &b.d2[static_cast<std::size_t>(g.row) * 8];
      if (adding) {
        for (int x = g.xa; x <= g.xb; ++x) {
          const auto v = static_cast<std::uint16_t>(g.h + (x - g.sx) * (x - g.sx));
          row[x] = v <= limit && v < row[x] ? static_cast<T>(v) : row[x];
        }
      } else {
        std::uint64_t bits = 0;
        for (int x = g.xa; x <= g.xb; ++x) {
          const auto v = static_cast<std::uint16_t>(g.h + (x - g.sx) * (x - g.sx));
          bits |= static_cast<std::uint64_t>(row[x] == v) << x;
        }
        t.marked[g.row >> 3] |= bits << ((g.row & 7) * 8);
        t.any_marked = t.any_marked || bits != 0;
      }
    }
  }
}

template <class T>
std::size_t DistanceField::recomputeBlock(Target<T>& t, std::vector<std::uint64_t>& window) const {
  const auto bc = block::coordsOf(t.key);
  const int w = 8 + 2 * radius_;
  const int wx0 = static_cast<int>(bc[0]) * 8 - radius_;
  const int wy0 = static_cast<int>(bc[1]) * 8 - radius_;
  const int wz0 = static_cast<int>(bc[2]) * 8 - radius_;
  window.assign(static_cast<std::size_t>(w * w), 0);
  // The occupied cells of the window, a block at a time.
  auto blockRange = [](int lo, int size) {
    return std::pair{std::max(lo, 0) >> 3, std::min(lo + size - 1, 0xffff) >> 3};
  };
  const auto [bx0, bx1] = blockRange(wx0, w);
  const auto [by0, by1] = blockRange(wy0, w);
  const auto [bz0, bz1] = blockRange(wz0, w);
  for (int bz = bz0; bz <= bz1; ++bz) {
    for (int by = by0; by <= by1; ++by) {
      for (int bx = bx0; bx <= bx1; ++bx) {
        const block::BlockMask* found = sources_.get(packBlock(bx, by, bz));
        if (found == nullptr) continue;
        const int shift = bx * 8 - wx0;
        for (int zz = 0; zz < 8; ++zz) {
          const int z = bz * 8 + zz - wz0;
          if (z < 0 || z >= w || (*found)[static_cast<std::size_t>(zz)] == 0) continue;
          for (int yy = 0; yy < 8; ++yy) {
            const int y = by * 8 + yy - wy0;
            if (y < 0 || y >= w) continue;
            const std::uint64_t byte = rowByte(*found, yy, zz);
            window[static_cast<std::size_t>(y + z * w)] |=
                shift >= 0 ? byte << shift : byte >> -shift;
          }
        }
      }
    }
  }
  auto row = [&](int cx, int y, int z, int) -> std::uint64_t {
    const std::uint64_t bits = window[static_cast<std::size_t>((y - wy0) + (z - wz0) * w)];
    const int px = cx - wx0;
    return px >= 31 ? bits >> (px - 31) : bits << (31 - px);
  };
  std::size_t count = 0;
  Block<T>& b = *t.block;
  block::forEachSetBit(t.marked, [&](int i) {
    // A marked cell holds the distance of a removed cell it was nearest to; every occupied
    // cell left or added is at least as far (an added one nearer would have lowered it): a cell
    // found at that distance is the nearest.
    const std::uint32_t d2 = nearestInRows(CellCoord::of(block::keyOf(t.key, i)), radius2_ + 1,
                                           rows_, row, nullptr, b.d2[static_cast<std::size_t>(i)]);
    b.d2[static_cast<std::size_t>(i)] =
        d2 > radius2_ ? std::numeric_limits<T>::max() : static_cast<T>(d2);
    ++count;
  });
  return count;
}

}  // namespace densemap
