#pragma once

#include <array>
#include <cstdint>
#include <unordered_map>

#include "densemap/geometry/block_layout.hpp"
#include "densemap/map/stable_vector.hpp"

namespace densemap {

/// The block store's entries by region of 8^3 blocks (64^3 voxels): what forEachEntryIn and
/// forEachRegionWriter walk, so that a box costs the entries in and near it, not the whole map
/// (writer only). A region's entries sit in a chain of pages of 62 taken from one pool that
/// grows a chunk at a time: a new block allocates nothing, and a new region only its hash
/// node. (A vector per region allocated ~30 times a scan at 0.1 m as regions filled, and with
/// the allocator's free chunks just swollen by another part of the process each allocation
/// walked thousands of them.)
template <class Entry>
class RegionIndex {
  struct Page {
    std::array<Entry*, 62> entries;  // with the count and link: 512 bytes
    std::uint32_t count = 0;
    Page* next = nullptr;
  };
  struct Chain {
    Page* first;
    Page* last;
  };

 public:
  static constexpr int kShift = 3;

  [[nodiscard]] static std::uint64_t keyOf(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
    return std::uint64_t{x} | (std::uint64_t{y} << 10) | (std::uint64_t{z} << 20);
  }
  [[nodiscard]] static std::uint64_t regionOf(std::uint64_t block_key) {
    const auto c = block::coordsOf(block_key);
    return keyOf(c[0] >> kShift, c[1] >> kShift, c[2] >> kShift);
  }

  void add(Entry* e) {
    auto [it, created] = chains_.try_emplace(regionOf(e->key), Chain{nullptr, nullptr});
    Chain& chain = it->second;
    if (created) {
      chain.first = chain.last = &pages_.emplace_back();
    } else if (chain.last->count == chain.last->entries.size()) {
      chain.last->next = &pages_.emplace_back();
      chain.last = chain.last->next;
    }
    chain.last->entries[chain.last->count++] = e;
  }
  void clear() {
    chains_.clear();
    pages_.clear();
  }
  [[nodiscard]] std::size_t regions() const { return chains_.size(); }
  /// Bytes held: the pages' pool and about a hash node and bucket per region.
  [[nodiscard]] std::size_t bytes() const { return pages_.capacityBytes() + chains_.size() * 64; }

  /// Calls f(entry) for every entry whose block lies in `box`.
  template <typename F>
  void forEachIn(const block::BlockBox& box, F&& f) const {
    const auto visit = [&](const Chain& chain) {
      forEachOf(chain, [&](const Entry* e) {
        if (box.contains(e->key)) f(*e);
      });
    };
    std::size_t box_regions = 1;
    for (int a = 0; a < 3; ++a) {
      box_regions *= std::size_t{(box.max[a] >> kShift) - (box.min[a] >> kShift) + 1};
    }
    if (box_regions > chains_.size()) {  // fewer regions in the map than in the box
      for (const auto& [key, chain] : chains_) visit(chain);
      return;
    }
    for (std::uint32_t z = box.min[2] >> kShift; z <= box.max[2] >> kShift; ++z) {
      for (std::uint32_t y = box.min[1] >> kShift; y <= box.max[1] >> kShift; ++y) {
        for (std::uint32_t x = box.min[0] >> kShift; x <= box.max[0] >> kShift; ++x) {
          const auto it = chains_.find(keyOf(x, y, z));
          if (it != chains_.end()) visit(it->second);
        }
      }
    }
  }
  /// Calls f(box, for_each) for every region holding entries: the region's box of blocks, and
  /// a function that calls its argument with each of the region's entries (Entry*).
  template <typename F>
  void forEachRegion(F&& f) {
    for (auto& [key, chain] : chains_) {
      block::BlockBox box;
      for (int a = 0; a < 3; ++a) {
        const auto c = static_cast<std::uint32_t>((key >> (10 * a)) & 0x3ff);
        box.min[a] = c << kShift;
        box.max[a] = std::min<std::uint32_t>(((c + 1) << kShift) - 1, 0x1fff);
      }
      f(box, [&](auto&& g) { forEachOf(chain, g); });
    }
  }

 private:
  template <typename G>
  static void forEachOf(const Chain& chain, G&& g) {
    for (const Page* p = chain.first; p != nullptr; p = p->next) {
      for (std::uint32_t i = 0; i < p->count; ++i) g(p->entries[i]);
    }
  }

  std::unordered_map<std::uint64_t, Chain> chains_;
  StableVector<Page, 8, 1024> pages_;
};

}  // namespace densemap
