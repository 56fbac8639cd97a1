#include "densemap/query/version_delta.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace densemap {

bool VersionDelta::wellFormed() const {
  if (block_keys.size() != block_ends.size() || cells.size() != log_odds.size()) return false;
  std::uint32_t previous = 0;
  for (const std::uint32_t end : block_ends) {
    if (end < previous || end > cells.size()) return false;
    previous = end;
  }
  if (!block_ends.empty() && block_ends.back() != cells.size()) return false;
  for (const std::uint16_t c : cells) {
    if (c >= block::kVoxels) return false;
  }
  return true;
}

void VersionDelta::closeBlock(std::uint64_t block_key) {
  const std::uint32_t begin = block_ends.empty() ? 0 : block_ends.back();
  if (cells.size() == begin) return;  // no cell of this block: no entry
  block_keys.push_back(block_key);
  block_ends.push_back(static_cast<std::uint32_t>(cells.size()));
}

CellChanges VersionDelta::changes() const {
  CellChanges out;
  out.reserve(cells.size());
  std::size_t begin = 0;
  for (std::size_t b = 0; b < block_keys.size(); ++b) {
    for (std::size_t i = begin; i < block_ends[b]; ++i) {
      const float v = log_odds[i];
      out.push_back(
          {block::keyOf(block_keys[b], cells[i]), std::isnan(v) ? 0.0F : v, !std::isnan(v)});
    }
    begin = block_ends[b];
  }
  return out;
}

VersionDelta diffVersions(const MapView& base, const MapView& next,
                          std::span<const std::uint64_t> blocks) {
  VersionDelta d;
  static const VoxelBlock kEmpty{};
  std::vector<std::uint64_t> sorted(blocks.begin(), blocks.end());
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  for (const std::uint64_t key : sorted) {
    const VoxelBlock* a = base.block(key);
    const VoxelBlock* b = next.block(key);
    if (a == b) continue;  // the same node: unchanged between the versions
    if (a == nullptr) a = &kEmpty;
    if (b == nullptr) b = &kEmpty;
    block::BlockMask either;
    for (int w = 0; w < block::kMaskWords; ++w) either[w] = a->known[w] | b->known[w];
    block::forEachSetBit(either, [&](int i) {
      const bool in_a = a->isKnown(i), in_b = b->isKnown(i);
      if (in_a && in_b && a->log_odds[i] == b->log_odds[i]) return;
      d.cells.push_back(static_cast<std::uint16_t>(i));
      d.log_odds.push_back(in_b ? b->log_odds[i] : std::numeric_limits<float>::quiet_NaN());
    });
    d.closeBlock(key);
  }
  return d;
}

std::uint64_t tileOf(const VoxelKey& k) {
  return std::uint64_t{static_cast<std::uint16_t>(k.x >> 5)} |
         (std::uint64_t{static_cast<std::uint16_t>(k.y >> 5)} << 11) |
         (std::uint64_t{static_cast<std::uint16_t>(k.z >> 5)} << 22);
}

std::uint64_t tileOfBlock(std::uint64_t block_key) { return tileOf(block::keyOf(block_key, 0)); }

std::unordered_map<std::uint64_t, std::vector<std::uint64_t>> tilesOf(const MapView& view) {
  std::unordered_map<std::uint64_t, std::vector<std::uint64_t>> tiles;
  view.forEachBlock([&](std::uint64_t block_key, const VoxelBlock&) {
    tiles[tileOfBlock(block_key)].push_back(block_key);
  });
  for (auto& [tile, blocks] : tiles) std::sort(blocks.begin(), blocks.end());
  return tiles;
}

VersionDelta cellsOf(const MapView& view, std::span<const std::uint64_t> blocks) {
  VersionDelta d;
  for (const std::uint64_t key : blocks) {
    const VoxelBlock* b = view.block(key);
    if (b == nullptr) continue;
    block::forEachSetBit(b->known, [&](int i) {
      d.cells.push_back(static_cast<std::uint16_t>(i));
      d.log_odds.push_back(b->log_odds[i]);
    });
    d.closeBlock(key);
  }
  return d;
}

}  // namespace densemap
