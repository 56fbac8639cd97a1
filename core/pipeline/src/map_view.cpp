#include "densemap/pipeline/map_view.hpp"

namespace densemap {

std::shared_ptr<const MapView> MapView::fromMap(const OccupancyMap& map, std::uint64_t version) {
  std::unordered_map<std::uint64_t, std::shared_ptr<VoxelBlock>> building;
  map.forEachKnown([&](const VoxelKey& k, float v) {
    auto& b = building[block::blockOf(k)];
    if (!b) b = std::make_shared<VoxelBlock>();
    const int i = block::indexOf(k);
    b->log_odds[i] = v;
    b->markKnown(i);
  });
  Blocks blocks(building.begin(), building.end());
  return std::make_shared<const MapView>(map.resolution(), version, std::move(blocks),
                                         map.knownCells());
}

std::shared_ptr<const MapView> MapView::withChanges(const CellChanges& changes,
                                                    std::uint64_t new_version) const {
  Blocks blocks = blocks_;
  std::unordered_map<std::uint64_t, std::shared_ptr<VoxelBlock>> copied;
  std::size_t known = known_cells_;
  for (const CellChange& c : changes) {
    const std::uint64_t bk = block::blockOf(c.key);
    auto& mine = copied[bk];
    if (!mine) {
      const auto it = blocks.find(bk);
      mine = it != blocks.end() ? std::make_shared<VoxelBlock>(*it->second)
                                : std::make_shared<VoxelBlock>();
    }
    const int i = block::indexOf(c.key);
    const bool was_known = mine->isKnown(i);
    if (c.known) {
      mine->log_odds[i] = c.log_odds;
      if (!was_known) {
        mine->markKnown(i);
        ++known;
      }
    } else if (was_known) {
      mine->known[i >> 6] &= ~(std::uint64_t{1} << (i & 63));
      --known;
    }
  }
  for (auto& [bk, b] : copied) blocks[bk] = std::move(b);
  return std::make_shared<const MapView>(grid_.resolution(), new_version, std::move(blocks), known);
}

std::optional<float> MapView::logOdds(const VoxelKey& key) const {
  const auto it = blocks_.find(block::blockOf(key));
  if (it == blocks_.end()) return std::nullopt;
  const int i = block::indexOf(key);
  if (!it->second->isKnown(i)) return std::nullopt;
  return it->second->log_odds[i];
}

void MapView::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  for (const auto& [bk, b] : blocks_) {
    for (int i = 0; i < block::kVoxels; ++i) {
      if (b->isKnown(i)) f(block::keyOf(bk, i), b->log_odds[i]);
    }
  }
}

}  // namespace densemap
