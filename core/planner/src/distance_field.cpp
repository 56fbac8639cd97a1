#include "densemap/planner/distance_field.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <string>

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
  std::stable_sort(rows_.begin(), rows_.end(),
                   [](const BallRow& a, const BallRow& b) { return a.h < b.h; });
}

void DistanceField::clear() {
  blocks_.clear();
  sources_.clear();
}

std::size_t DistanceField::memoryBytes() const {
  // Each entry: the node (key, pointer, hash link) and the bucket; each field block itself.
  constexpr std::size_t kNode = 4 * sizeof(void*);
  return blocks_.size() * (sizeof(Block) + kNode) + blocks_.bucket_count() * sizeof(void*) +
         sources_.size() * (sizeof(block::BlockMask) + kNode) +
         sources_.bucket_count() * sizeof(void*);
}

std::uint16_t DistanceField::distanceSquared(const VoxelKey& cell) const {
  const auto it = blocks_.find(block::blockOf(cell));
  return it == blocks_.end() ? kFar : it->second->d2[block::indexOf(cell)];
}

bool DistanceField::isOccupied(const VoxelKey& cell) const {
  const auto it = sources_.find(block::blockOf(cell));
  return it != sources_.end() && block::testBit(it->second, block::indexOf(cell));
}

std::uint64_t DistanceField::occupiedRow(int cx, int y, int z, int ext) const {
  if (y < 0 || y > 0xffff || z < 0 || z > 0xffff) return 0;
  const int lo = std::max(cx - ext, 0);
  const int hi = std::min(cx + ext, 0xffff);
  std::uint64_t bits = 0;
  for (int bx = lo >> 3; bx <= hi >> 3; ++bx) {
    const auto it = sources_.find(packBlock(bx, y >> 3, z >> 3));
    if (it == sources_.end()) continue;
    const std::uint64_t byte = rowByte(it->second, y, z);
    const int shift = bx * 8 - (cx - 31);  // where the block's x = 0 lands
    if (shift >= 64) continue;
    bits |= shift >= 0 ? byte << shift : byte >> -shift;
  }
  return bits;
}

std::optional<VoxelKey> DistanceField::nearestOccupied(const VoxelKey& cell) const {
  const std::uint16_t d2 = distanceSquared(cell);
  if (d2 == kFar) return std::nullopt;
  std::array<int, 3> off{};
  const CellCoord c = CellCoord::of(cell);
  (void)nearestInRows(
      c, std::uint32_t{d2} + 1, rows_,
      [this](int cx, int y, int z, int ext) { return occupiedRow(cx, y, z, ext); }, &off);
  return CellCoord{c.x + off[0], c.y + off[1], c.z + off[2]}.key();
}

DistanceUpdateStats DistanceField::update(const MapView& view,
                                          std::span<const std::uint64_t> blocks,
                                          const ChunkRunner& runner) {
  std::vector<CellCoord> added;
  std::vector<CellCoord> removed;
  for (const std::uint64_t key : blocks) {
    const block::BlockMask now = occupiedOf(view.block(key));
    const auto it = sources_.find(key);
    const block::BlockMask before = it == sources_.end() ? block::BlockMask{} : it->second;
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
    } else if (it != sources_.end()) {
      sources_.erase(it);
    }
  }
  DistanceUpdateStats stats;
  apply(added, removed, stats, runner);
  stats.field_blocks = blocks_.size();
  return stats;
}

DistanceUpdateStats DistanceField::rebuild(const MapView& view, const ChunkRunner& runner) {
  clear();
  std::vector<std::uint64_t> keys;
  view.forEachBlock([&](std::uint64_t key, const VoxelBlock&) { keys.push_back(key); });
  return update(view, keys, runner);
}

void DistanceField::apply(const std::vector<CellCoord>& added,
                          const std::vector<CellCoord>& removed, DistanceUpdateStats& stats,
                          const ChunkRunner& runner) {
  stats.added = added.size();
  stats.removed = removed.size();
  if (added.empty() && removed.empty()) return;
  const int r = radius_;
  // The changed cells, each with the occupied cells (as they are now) within 2 cells of it.
  Changes changes;
  auto record = [&](const CellCoord& c) {
    const auto begin = static_cast<std::uint32_t>(changes.near.size());
    for (int dz = -2; dz <= 2; ++dz) {
      for (int dy = -2; dy <= 2; ++dy) {
        const int y = c.y + dy, z = c.z + dz;
        if (y < 0 || y > 0xffff || z < 0 || z > 0xffff) continue;
        const std::uint64_t bits = occupiedRow(c.x, y, z, 2);
        for (int dx = -2; dx <= 2; ++dx) {
          if ((dx != 0 || dy != 0 || dz != 0) && ((bits >> (31 + dx)) & 1U) != 0) {
            changes.near.push_back({dx, dy, dz, dx * dx + dy * dy + dz * dz});
          }
        }
      }
    }
    std::sort(changes.near.begin() + begin, changes.near.end(),
              [](const auto& u, const auto& v) { return u[3] < v[3]; });
    changes.list.push_back({c, begin, static_cast<std::uint32_t>(changes.near.size())});
  };
  // The blocks of the field each changed cell's ball reaches.
  std::unordered_map<std::uint64_t, Work> work;
  auto spread = [&](const CellCoord& s, bool add) {
    record(s);
    const auto index = static_cast<std::uint32_t>(changes.list.size() - 1);
    const int x0 = std::max(s.x - r, 0) >> 3, x1 = std::min(s.x + r, 0xffff) >> 3;
    const int y0 = std::max(s.y - r, 0) >> 3, y1 = std::min(s.y + r, 0xffff) >> 3;
    const int z0 = std::max(s.z - r, 0) >> 3, z1 = std::min(s.z + r, 0xffff) >> 3;
    for (int bz = z0; bz <= z1; ++bz) {
      for (int by = y0; by <= y1; ++by) {
        for (int bx = x0; bx <= x1; ++bx) {
          Work& w = work[packBlock(bx, by, bz)];
          (add ? w.add : w.remove).push_back(index);
        }
      }
    }
  };
  for (const CellCoord& s : added) spread(s, true);
  for (const CellCoord& s : removed) spread(s, false);

  // Blocks first (serially: the table changes), then each block's work on the runner: a
  // block's task writes only that block and reads the occupied cells, which stay as they are.
  std::vector<Target> targets;
  targets.reserve(work.size());
  for (auto& [key, w] : work) {
    Block* b = nullptr;
    if (auto it = blocks_.find(key); it != blocks_.end()) {
      b = it->second.get();
    } else if (!w.add.empty()) {
      b = blocks_.emplace(key, std::make_unique<Block>()).first->second.get();
    } else {
      continue;  // no finite cell here: no removed cell was anyone's nearest
    }
    targets.push_back({key, b, &w, &changes, {}, false});
  }
  runner.run(targets.size(), 8, [&](std::size_t begin, std::size_t end) {
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
  for (const Target& t : targets) {
    if (std::all_of(t.block->d2.begin(), t.block->d2.end(),
                    [](std::uint16_t v) { return v == kFar; })) {
      blocks_.erase(t.key);
    }
  }
}

void DistanceField::stampBlock(Target& t) const {
  const auto r2 = static_cast<int>(radius2_);
  const auto bc = block::coordsOf(t.key);
  const int ox = static_cast<int>(bc[0]) * 8, oy = static_cast<int>(bc[1]) * 8,
            oz = static_cast<int>(bc[2]) * 8;
  // f(y, z (block-relative), h, dx^2 of the row's 8 cells) for each x-row of the block that the
  // source's ball reaches: all 8 cells at once (cells beyond the ball have h + dx^2 > r2).
  auto forRows = [&](std::uint32_t index, auto&& f) {
    const Change& change = t.changes->list[index];
    const CellCoord& s = change.cell;
    if (s.x + radius_ < ox || s.x - radius_ > ox + 7) return;
    const std::span<const std::array<int, 4>> near(t.changes->near.data() + change.near_begin,
                                                   change.near_end - change.near_begin);
    // A cell at offset v from s keeps s's value only if 2 v.n <= |n|^2 for every near cell n.
    for (const auto& n : near) {
      // The block's smallest 2 v.n (at a corner): above |n|^2, n is nearer to all of it.
      int low = 0;
      const int lo[3] = {ox - s.x, oy - s.y, oz - s.z};
      for (int k = 0; k < 3; ++k)
        low += 2 * n[static_cast<std::size_t>(k)] *
               (n[static_cast<std::size_t>(k)] >= 0 ? lo[k] : lo[k] + 7);
      if (low > n[3]) return;
    }
    std::array<std::uint16_t, 8> dx2{};
    for (int x = 0; x < 8; ++x) {
      const int dx = std::min(std::abs(ox + x - s.x), 255);
      dx2[static_cast<std::size_t>(x)] = static_cast<std::uint16_t>(dx * dx);
    }
    const int za = std::max(oz, s.z - radius_), zb = std::min(oz + 7, s.z + radius_);
    const int ya = std::max(oy, s.y - radius_), yb = std::min(oy + 7, s.y + radius_);
    for (int z = za; z <= zb; ++z) {
      for (int y = ya; y <= yb; ++y) {
        const int dy = y - s.y, dz = z - s.z;
        const int h = dz * dz + dy * dy;
        if (h > r2) continue;
        // The row's x-offsets [lo, hi] (block-relative x) that no near cell excludes.
        int lo = 0, hi = 7;
        for (const auto& n : near) {
          const int k = n[3] - 2 * (dy * n[1] + dz * n[2]);  // keep 2 dx n.x <= k
          if (n[0] == 0) {
            if (k < 0) lo = 8;
          } else if (n[0] > 0) {
            hi = std::min(hi, s.x - ox + floorDiv(k, 2 * n[0]));
          } else {
            lo = std::max(lo, s.x - ox - floorDiv(k, -2 * n[0]));
          }
          if (lo > hi) break;
        }
        if (lo > hi) continue;
        f(y - oy, z - oz, static_cast<std::uint16_t>(h), dx2, lo, hi);
      }
    }
  };
  Block& b = *t.block;
  const auto limit = static_cast<std::uint16_t>(r2);
  for (const std::uint32_t s : t.work->remove) {
    forRows(s, [&](int y, int z, std::uint16_t h, const std::array<std::uint16_t, 8>& dx2, int lo,
                   int hi) {
      const std::uint16_t* row = &b.d2[static_cast<std::size_t>((y << 3) | (z << 6))];
      std::uint64_t bits = 0;
      for (std::size_t x = 0; x < 8; ++x) {
        const auto v = static_cast<std::uint16_t>(h + dx2[x]);
        const bool in = static_cast<int>(x) >= lo && static_cast<int>(x) <= hi;
        bits |= static_cast<std::uint64_t>(in && v <= limit && row[x] == v) << x;
      }
      t.marked[static_cast<std::size_t>(z)] |= bits << (y * 8);
      t.any_marked = t.any_marked || bits != 0;
    });
  }
  for (const std::uint32_t s : t.work->add) {
    forRows(s, [&](int y, int z, std::uint16_t h, const std::array<std::uint16_t, 8>& dx2, int lo,
                   int hi) {
      std::uint16_t* row = &b.d2[static_cast<std::size_t>((y << 3) | (z << 6))];
      for (std::size_t x = 0; x < 8; ++x) {
        const auto v = static_cast<std::uint16_t>(h + dx2[x]);
        const bool in = static_cast<int>(x) >= lo && static_cast<int>(x) <= hi;
        row[x] = in && v <= limit && v < row[x] ? v : row[x];
      }
    });
  }
}

std::size_t DistanceField::recomputeBlock(Target& t, std::vector<std::uint64_t>& window) const {
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
        const auto it = sources_.find(packBlock(bx, by, bz));
        if (it == sources_.end()) continue;
        const int shift = bx * 8 - wx0;
        for (int zz = 0; zz < 8; ++zz) {
          const int z = bz * 8 + zz - wz0;
          if (z < 0 || z >= w || it->second[static_cast<std::size_t>(zz)] == 0) continue;
          for (int yy = 0; yy < 8; ++yy) {
            const int y = by * 8 + yy - wy0;
            if (y < 0 || y >= w) continue;
            const std::uint64_t byte = rowByte(it->second, yy, zz);
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
  Block& b = *t.block;
  block::forEachSetBit(t.marked, [&](int i) {
    const std::uint32_t d2 =
        nearestInRows(CellCoord::of(block::keyOf(t.key, i)), radius2_ + 1, rows_, row);
    b.d2[static_cast<std::size_t>(i)] = d2 > radius2_ ? kFar : static_cast<std::uint16_t>(d2);
    ++count;
  });
  return count;
}

}  // namespace densemap
