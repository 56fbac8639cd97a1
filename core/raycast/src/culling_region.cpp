#include "densemap/raycast/culling_region.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <bit>

namespace densemap {

KeyBox cullingBox(const VoxelKey& origin, const KeyBox& rays_box, std::size_t max_voxels) {
  KeyBox box = rays_box;
  for (int a = 0; a < 3; ++a) {
    box.min[a] = std::min(box.min[a], origin[a]);
    box.max[a] = std::max(box.max[a], origin[a]);
  }
  const auto voxels = [](const KeyBox& b) {
    std::size_t n = 1;
    for (int a = 0; a < 3; ++a) n *= static_cast<std::size_t>(b.max[a] - b.min[a]) + 1;
    return n;
  };
  if (voxels(box) <= max_voxels) return box;
  // Largest half-width h (binary search) such that the box clipped to origin +- h fits.
  const auto clipped = [&](unsigned h) {
    KeyBox c = box;
    for (int a = 0; a < 3; ++a) {
      c.min[a] =
          static_cast<std::uint16_t>(std::max<int>(c.min[a], origin[a] - static_cast<int>(h)));
      c.max[a] =
          static_cast<std::uint16_t>(std::min<int>(c.max[a], origin[a] + static_cast<int>(h)));
    }
    return c;
  };
  unsigned lo = 0, hi = 65535;
  while (lo < hi) {
    const unsigned mid = (lo + hi + 1) / 2;
    if (voxels(clipped(mid)) <= max_voxels) {
      lo = mid;
    } else {
      hi = mid - 1;
    }
  }
  return clipped(lo);
}

void CullingRegion::loadFullyFree(const OccupancyMap& map) {
  const std::uint64_t bx0 = min_.x >> block::kShift, bx1 = (min_.x + nx_ - 1) >> block::kShift;
  const std::uint64_t by0 = min_.y >> block::kShift, by1 = (min_.y + ny_ - 1) >> block::kShift;
  const std::uint64_t bz0 = min_.z >> block::kShift, bz1 = (min_.z + nz_ - 1) >> block::kShift;
  const block::BlockBox box{
      .min = {static_cast<std::uint32_t>(bx0), static_cast<std::uint32_t>(by0),
              static_cast<std::uint32_t>(bz0)},
      .max = {static_cast<std::uint32_t>(bx1), static_cast<std::uint32_t>(by1),
              static_cast<std::uint32_t>(bz1)}};
  std::vector<FullyFreeBlock>& found = scratch_.found;
  found.clear();
  map.appendFullyFreeBlocks(box, found);
  loadBlocks(found);
}

bool CullingRegion::boxHasBlock(std::uint64_t key) const {
  const std::uint64_t bx = key & 0x1fff, by = (key >> 13) & 0x1fff, bz = (key >> 26) & 0x1fff;
  return bx >= (min_.x >> block::kShift) && bx <= ((min_.x + nx_ - 1) >> block::kShift) &&
         by >= (min_.y >> block::kShift) && by <= ((min_.y + ny_ - 1) >> block::kShift) &&
         bz >= (min_.z >> block::kShift) && bz <= ((min_.z + nz_ - 1) >> block::kShift);
}

void CullingRegion::loadBlocks(std::span<const FullyFreeBlock> blocks) {
  // The box's blocks, by layer of blocks along z (a counting sort; blocks outside the box are
  // dropped): blocks of different layers write different rows, so the layers load side by side.
  const std::uint64_t bz0 = min_.z >> block::kShift, bz1 = (min_.z + nz_ - 1) >> block::kShift;
  const auto layers = static_cast<std::size_t>(bz1 - bz0 + 1);
  std::vector<std::size_t>& starts = scratch_.layer_starts;
  starts.assign(layers + 1, 0);
  const auto layerOf = [bz0](std::uint64_t block_key) {
    return static_cast<std::size_t>(((block_key >> 26) & 0x1fff) - bz0);
  };
  for (const FullyFreeBlock& b : blocks) {
    if (boxHasBlock(b.key)) ++starts[layerOf(b.key) + 1];
  }
  for (std::size_t l = 0; l < layers; ++l) starts[l + 1] += starts[l];
  std::vector<FullyFreeBlock>& by_layer = scratch_.by_layer;
  by_layer.resize(starts[layers]);
  {
    std::vector<std::size_t> next(starts.begin(), starts.end() - 1);
    for (const FullyFreeBlock& b : blocks) {
      if (boxHasBlock(b.key)) by_layer[next[layerOf(b.key)]++] = b;
    }
  }
  tbb::parallel_for(std::size_t{0}, layers, [&](std::size_t l) {
    for (std::size_t i = starts[l]; i < starts[l + 1]; ++i) loadBlock(by_layer[i]);
  });
}

void CullingRegion::loadBlock(const FullyFreeBlock& b) {
  const std::uint64_t bx = b.key & 0x1fff, by = (b.key >> 13) & 0x1fff, bz = (b.key >> 26) & 0x1fff;
  // Mask word z holds the block's 8x8 voxels of layer z, byte y the row along x: only the
  // non-zero bytes are visited (a ray's marks fill a few rows of a block).
  const int x0 = static_cast<int>(bx << block::kShift) - min_.x;
  const unsigned gx = static_cast<unsigned>(std::max(x0, 0));
  // The box's part of the row: bits before the box (it starts inside this block) and past it.
  std::uint64_t keep = 0xffU;
  if (x0 < 0) keep >>= -x0;
  if (gx + 8 > nx_) keep &= (std::uint64_t{1} << (nx_ - gx)) - 1;
  const unsigned word = gx >> 6, bit = gx & 63;
  const bool spills = bit > 56 && word + 1 < words_per_row_;
  for (int z = 0; z < block::kEdge; ++z) {
    std::uint64_t layer = b.mask[static_cast<std::size_t>(z)];
    if (layer == 0) continue;
    const int gz = static_cast<int>(bz << block::kShift) + z - min_.z;
    if (gz < 0 || gz >= static_cast<int>(nz_)) continue;
    while (layer != 0) {
      const int y = std::countr_zero(layer) >> 3;
      std::uint64_t bits8 = (layer >> (8 * y)) & 0xffU;
      layer &= ~(std::uint64_t{0xff} << (8 * y));
      const int gy = static_cast<int>(by << block::kShift) + y - min_.y;
      if (gy < 0 || gy >= static_cast<int>(ny_)) continue;
      if (x0 < 0) bits8 >>= -x0;
      bits8 &= keep;
      if (bits8 == 0) continue;
      std::uint64_t* r = loadRow(static_cast<unsigned>(gy), static_cast<unsigned>(gz));
      r[word] |= bits8 << bit;
      if (spills) r[word + 1] |= bits8 >> (64 - bit);
    }
  }
}

void CullingRegion::toBricks(const KeyBox& frame, bool clear) {
  for (int a = 0; a < 3; ++a) {
    brick_min_[a] = static_cast<unsigned>(frame.min[a] >> block::kShift);
    bricks_n_[a] = static_cast<unsigned>(frame.max[a] >> block::kShift) - brick_min_[a] + 1;
  }
  const std::size_t bricks = static_cast<std::size_t>(bricks_n_[0]) * bricks_n_[1] * bricks_n_[2];
  if (clear || bricks_.size() != bricks) bricks_.assign(bricks, block::BlockMask{});
  // A row's voxels go to its bricks a byte (8 voxels along x, one brick's row) at a time: the
  // row's bit x is voxel min_.x + x, so brick byte k holds row bits [8k - offset, 8k - offset
  // + 8) with offset = min_.x % 8. Each non-zero byte once, per set bit's first byte.
  const unsigned offset = min_.x & (block::kEdge - 1);
  const unsigned first_brick = (min_.x >> block::kShift) - brick_min_[0];
  // The rows of one layer of bricks along z write only that layer's bricks: layers in parallel.
  const unsigned first_layer = min_.z >> block::kShift,
                 last_layer = (min_.z + nz_ - 1) >> block::kShift;
  tbb::parallel_for(first_layer, last_layer + 1, [&](unsigned layer) {
    const unsigned z_from = std::max(layer << block::kShift, unsigned{min_.z}) - min_.z;
    const unsigned z_to = std::min((layer + 1) << block::kShift, unsigned{min_.z} + nz_) - min_.z;
    for (unsigned z = z_from; z < z_to; ++z) {
      for (unsigned y = 0; y < ny_; ++y) {
        const std::uint64_t* r = row(y, z);
        const unsigned gy = min_.y + y, gz = min_.z + z;
        const std::size_t brick_row =
            (static_cast<std::size_t>((gz >> block::kShift) - brick_min_[2]) * bricks_n_[1] +
             ((gy >> block::kShift) - brick_min_[1])) *
            bricks_n_[0];
        const unsigned shift = 8 * (gy & (block::kEdge - 1));
        const unsigned layer_z = gz & (block::kEdge - 1);
        for (unsigned w = 0; w < words_per_row_; ++w) {
          std::uint64_t bits = r[w];
          while (bits != 0) {
            const unsigned x = w * 64 + static_cast<unsigned>(std::countr_zero(bits));
            const unsigned k = (x + offset) >> block::kShift;  // its brick byte
            const int start = static_cast<int>(8 * k) - static_cast<int>(offset);
            std::uint64_t byte = 0;
            if (start < 0) {
              byte = r[0] << -start;
            } else {
              const unsigned sw = static_cast<unsigned>(start) >> 6,
                             sb = static_cast<unsigned>(start) & 63;
              byte = r[sw] >> sb;
              if (sb > 56 && sw + 1 < words_per_row_) byte |= r[sw + 1] << (64 - sb);
            }
            bricks_[brick_row + first_brick + k][layer_z] |= (byte & 0xffU) << shift;
            // This word's bits of that byte are done.
            const int end = start + 8 - static_cast<int>(w * 64);  // first bit past the byte
            bits = end >= 64 ? 0 : bits & (~std::uint64_t{0} << end);
          }
        }
      }
    }
  });
}

void CullingRegion::keepRunThrough(std::uint64_t* r, unsigned x0) const {
  const unsigned w0 = x0 >> 6, b0 = x0 & 63;
  if (((r[w0] >> b0) & 1U) == 0) {
    std::fill(r, r + words_per_row_, 0);
    return;
  }
  // First clear bit above x0 (bits past nx_ are always clear, so one is found).
  unsigned hi = nx_;
  for (unsigned w = w0; w < words_per_row_; ++w) {
    std::uint64_t zeros = ~r[w];
    if (w == w0) zeros &= ~std::uint64_t{0} << b0;
    if (zeros != 0) {
      hi = w * 64 + static_cast<unsigned>(std::countr_zero(zeros));
      break;
    }
  }
  // Last clear bit below x0, or -1.
  int lo = -1;
  for (int w = static_cast<int>(w0); w >= 0; --w) {
    std::uint64_t zeros = ~r[w];
    if (w == static_cast<int>(w0))
      zeros &= b0 == 63 ? ~std::uint64_t{0} : ((std::uint64_t{1} << (b0 + 1)) - 1);
    if (zeros != 0) {
      lo = w * 64 + 63 - std::countl_zero(zeros);
      break;
    }
  }
  // Keep bits lo+1 .. hi-1.
  for (unsigned w = 0; w < words_per_row_; ++w) {
    const int first = static_cast<int>(w * 64);
    std::uint64_t keep = ~std::uint64_t{0};
    const int from = lo + 1 - first;              // keep bits >= from
    const int to = static_cast<int>(hi) - first;  // keep bits < to
    if (from >= 64 || to <= 0) {
      keep = 0;
    } else {
      if (from > 0) keep &= ~std::uint64_t{0} << from;
      if (to < 64) keep &= (std::uint64_t{1} << to) - 1;
    }
    r[w] &= keep;
  }
}

void CullingRegion::build(const OccupancyMap& map, const VoxelKey& origin, const KeyBox& box,
                          std::span<const VoxelKey> hit, const KeyBox* frame, bool growable) {
  min_ = box.min;
  nx_ = static_cast<unsigned>(box.max.x - box.min.x) + 1;
  ny_ = static_cast<unsigned>(box.max.y - box.min.y) + 1;
  nz_ = static_cast<unsigned>(box.max.z - box.min.z) + 1;
  words_per_row_ = (nx_ + 63) / 64;
  size_ = 0;
  origin_ = origin;
  growable_ = false;
  bool inside = frame != nullptr;
  for (int a = 0; a < 3 && inside; ++a) {
    inside = frame->min[a] <= box.min[a] && box.max[a] <= frame->max[a];
  }
  frame_ = inside ? *frame : box;

  // The region grows from O: when O itself cannot be in it (not fully free — always so for a
  // sensor that moved to a cell it has not crossed often enough — or ended in by a ray), it is
  // empty, and loading the box is skipped (unless the region is to grow by a scan's marks).
  const auto origin_value = map.logOdds(origin);
  const bool origin_hit = std::find(hit.begin(), hit.end(), origin) != hit.end();
  const bool origin_free = origin_value && map.sensorModel().isFullyFree(*origin_value);
  if (!growable && (!origin_free || origin_hit)) {
    bits_.clear();
    bricks_.clear();
    for (unsigned& n : bricks_n_) n = 0;
    return;
  }
  const std::size_t words = static_cast<std::size_t>(ny_) * nz_ * words_per_row_;
  growable_ = growable;
  if (growable) {
    loaded_.assign(words, 0);
    bits_.resize(words);  // every row is written by the sweep
  } else {
    bits_.assign(words, 0);
  }
  loadFullyFree(map);
  for (const VoxelKey& k : hit) {
    const unsigned x = static_cast<unsigned>(k.x) - min_.x;
    const unsigned y = static_cast<unsigned>(k.y) - min_.y;
    const unsigned z = static_cast<unsigned>(k.z) - min_.z;
    if (x >= nx_ || y >= ny_ || z >= nz_) continue;
    loadRow(y, z)[x >> 6] &= ~(std::uint64_t{1} << (x & 63));
  }
  sweepAndIndex();
}

void CullingRegion::grow(std::span<const FullyFreeBlock> covered) {
  if (!growable_) return;
  loadBlocks(covered);  // into the loaded rows, the sweep's source
  // The region only grows (its voxels stay covered): the bricks keep theirs.
  sweepAndIndex(/*clear=*/false);
}

void CullingRegion::sweepAndIndex(bool clear) {
  // Sweep outward from O: a row (y, z) needs the rows one step closer to O in y and in z. The
  // row through O first, then its plane's rows along y and its column's along z (each needs
  // only that row), then the four quadrants around them, each on its own (a quadrant's rows need
  // only its own and the plane's or the column's).
  const VoxelKey& origin = origin_;
  const unsigned ox = origin.x - min_.x, oy = origin.y - min_.y, oz = origin.z - min_.z;
  const auto sweepRow = [&](unsigned y, unsigned z, unsigned y_prev, unsigned z_prev) {
    std::uint64_t* r = row(y, z);
    const std::uint64_t* loaded = loadRow(y, z);  // r itself when swept in place
    if (loaded != r) std::copy(loaded, loaded + words_per_row_, r);
    if (y != y_prev) {
      const std::uint64_t* p = row(y_prev, z);
      for (unsigned w = 0; w < words_per_row_; ++w) r[w] &= p[w];
    }
    if (z != z_prev) {
      const std::uint64_t* p = row(y, z_prev);
      for (unsigned w = 0; w < words_per_row_; ++w) r[w] &= p[w];
    }
    keepRunThrough(r, ox);
    return block::countBits(r, words_per_row_);
  };
  // The values from `o` outward (up, then down) with each one's neighbour toward `o`.
  const auto outward = [](unsigned o, unsigned n, auto&& f) {
    for (unsigned v = o + 1; v < n; ++v) f(v, v - 1);
    for (unsigned v = o; v-- > 0;) f(v, v + 1);
  };
  size_ = sweepRow(oy, oz, oy, oz);
  std::size_t plane = 0, column = 0;
  tbb::parallel_invoke(
      [&] {
        outward(oy, ny_,
                [&](unsigned y, unsigned y_prev) { plane += sweepRow(y, oz, y_prev, oz); });
      },
      [&] {
        outward(oz, nz_,
                [&](unsigned z, unsigned z_prev) { column += sweepRow(oy, z, oy, z_prev); });
      });
  std::array<std::size_t, 4> quadrants{};
  const auto quadrant = [&](int q) {
    const bool up_y = (q & 1) != 0, up_z = (q & 2) != 0;
    std::size_t n = 0;
    const auto ys = [&](auto&& f) {
      if (up_y) {
        for (unsigned y = oy + 1; y < ny_; ++y) f(y, y - 1);
      } else {
        for (unsigned y = oy; y-- > 0;) f(y, y + 1);
      }
    };
    const auto zs = [&](auto&& f) {
      if (up_z) {
        for (unsigned z = oz + 1; z < nz_; ++z) f(z, z - 1);
      } else {
        for (unsigned z = oz; z-- > 0;) f(z, z + 1);
      }
    };
    zs([&](unsigned z, unsigned z_prev) {
      ys([&](unsigned y, unsigned y_prev) { n += sweepRow(y, z, y_prev, z_prev); });
    });
    quadrants[static_cast<std::size_t>(q)] = n;
  };
  tbb::parallel_invoke([&] { quadrant(0); }, [&] { quadrant(1); }, [&] { quadrant(2); },
                       [&] { quadrant(3); });
  size_ += plane + column + quadrants[0] + quadrants[1] + quadrants[2] + quadrants[3];
  toBricks(frame_, clear);
}

}  // namespace densemap
