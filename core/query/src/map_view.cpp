#include "densemap/query/map_view.hpp"

namespace densemap {

std::shared_ptr<const MapView> MapView::publish(GridMap& map, std::size_t other_bytes,
                                                std::vector<std::uint64_t>* written_blocks) {
  const std::size_t known = map.knownCells();
  const std::size_t bytes = map.memoryBytes() + other_bytes;
  auto published = map.publishVersion();
  if (written_blocks != nullptr) *written_blocks = std::move(published.written_blocks);
  return std::make_shared<const MapView>(map.store(), std::move(published.pin), map.resolution(),
                                         published.version, known, bytes);
}

std::shared_ptr<const MapView> MapView::advanceLive(GridMap& map, std::size_t other_bytes,
                                                    std::vector<std::uint64_t>* written_blocks) {
  const std::size_t known = map.knownCells();
  const std::size_t bytes = map.memoryBytes() + other_bytes;
  auto ended = map.advanceVersion();
  if (written_blocks != nullptr) *written_blocks = std::move(ended.written_blocks);
  return std::make_shared<const MapView>(map.store(), nullptr, map.resolution(), ended.version,
                                         known, bytes);
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
    block::forEachSetBit(b.known, [&](int i) { f(block::keyOf(key, i), b.log_odds[i]); });
  });
}

}  // namespace densemap
