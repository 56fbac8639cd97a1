#include "densemap/pipeline/map_view.hpp"

#include <bit>

namespace densemap {

std::shared_ptr<const MapView> MapView::publish(GridMap& map) {
  const std::size_t known = map.knownCells();
  const std::size_t bytes = map.memoryBytes();
  auto published = map.publishVersion();
  return std::make_shared<const MapView>(map.store(), std::move(published.pin), map.resolution(),
                                         published.version, known, bytes);
}

std::shared_ptr<const MapView> MapView::fromMap(const OccupancyMap& map, std::uint64_t version) {
  GridMap copy(map.resolution(), map.sensorModel());
  map.forEachKnown([&](const VoxelKey& k, float v) { copy.setLogOdds(k, v); });
  copy.startVersionsAt(version);
  return publish(copy);
}

std::optional<float> MapView::logOdds(const VoxelKey& key) const {
  const VoxelBlock* b = block(block::blockOf(key));
  if (b == nullptr) return std::nullopt;
  const int i = block::indexOf(key);
  if (!b->isKnown(i)) return std::nullopt;
  return b->log_odds[i];
}

void MapView::forEachBlock(const std::function<void(std::uint64_t, const VoxelBlock&)>& f) const {
  store_->forEachEntry([&](const BlockEntry& e) {
    if (const BlockNode* n = BlockStore::nodeAt(e, version_); n != nullptr) f(e.key, n->voxels);
  });
}

void MapView::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  forEachBlock([&](std::uint64_t key, const VoxelBlock& b) {
    for (int w = 0; w < block::kMaskWords; ++w) {
      for (std::uint64_t bits = b.known[w]; bits != 0; bits &= bits - 1) {
        const int i = w * 64 + std::countr_zero(bits);
        f(block::keyOf(key, i), b.log_odds[i]);
      }
    }
  });
}

}  // namespace densemap
