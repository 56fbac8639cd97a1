#include "densemap/map/cell_update.hpp"
#include "densemap/map/octree_map.hpp"

namespace densemap {
namespace {

octomap::OcTreeKey toOcTreeKey(const VoxelKey& k) { return {k.x, k.y, k.z}; }

}  // namespace

void configureOcTree(octomap::OcTree& tree, const SensorModel& model) {
  // Same probabilities through OctoMap's own setters: the log-odds are equal by construction.
  const SensorProbabilities& p = model.probabilities();
  tree.setProbHit(p.hit);
  tree.setProbMiss(p.miss);
  tree.setClampingThresMin(p.clamp_min);
  tree.setClampingThresMax(p.clamp_max);
}

OctreeMap::OctreeMap(double resolution_m, const SensorModel& model)
    : OccupancyMap(resolution_m, model), tree_(resolution_m) {
  configureOcTree(tree_, model);
}

void OctreeMap::noteValue(const VoxelKey& key, float log_odds) {
  const int i = block::indexOf(key);
  if (sensorModel().isFullyFree(log_odds)) {
    block::setBit(fully_free_[block::blockOf(key)], i);
  } else if (const auto it = fully_free_.find(block::blockOf(key)); it != fully_free_.end()) {
    block::clearBit(it->second, i);
  }
}

ApplyStats OctreeMap::apply(const ScanUpdate& update, CellChanges* changes) {
  ApplyStats stats;
  const UpdateRule rule = update.rule();
  const SensorModel& model = sensorModel();
  refreshFullyFree();
  for (const auto& [block_key, cells] : update.blocks()) {
    const auto free_it = fully_free_.find(block_key);
    const block::BlockMask* fully_free = free_it == fully_free_.end() ? nullptr : &free_it->second;
    ScanUpdate::forEachCellInBlock(
        block_key, cells, [&](const VoxelKey& key, const CellHits& hits) {
          ++stats.updated_cells;
          // A cell at the lower clamp that is only crossed stays there: OctoMap's updateNode
          // returns early for it too ("no change: node already at threshold").
          if (hits.occupied == 0 && fully_free != nullptr &&
              block::testBit(*fully_free, block::indexOf(key))) {
            return;
          }
          const octomap::OcTreeKey k = toOcTreeKey(key);
          const octomap::OcTreeNode* before = tree_.search(k);
          const bool known = before != nullptr;
          const float old_value = known ? before->getLogOdds() : 0.0F;
          // OctoMap's own update paths: the boolean one under kSet, a log-odds delta under kPerRay.
          const octomap::OcTreeNode* after =
              rule == UpdateRule::kSet
                  ? tree_.updateNode(k, hits.occupied > 0, /*lazy_eval=*/false)
                  : tree_.updateNode(k, perRayDelta(model, hits), /*lazy_eval=*/false);
          const float new_value = after->getLogOdds();
          if (!known || new_value != old_value) {
            ++stats.changed_cells;
            noteValue(key, new_value);
            if (changes != nullptr) changes->push_back({key, new_value, true});
          }
        });
  }
  return stats;
}

void OctreeMap::insertWithOctomap(const PointCloud& points_world, const Point3f& origin_world,
                                  double max_range_m) {
  octomap::Pointcloud cloud;
  cloud.reserve(points_world.size());
  for (const auto& p : points_world) cloud.push_back(p.x(), p.y(), p.z());
  tree_.insertPointCloud(cloud,
                         octomap::point3d(origin_world.x(), origin_world.y(), origin_world.z()),
                         max_range_m, /*lazy_eval=*/false, /*discretize=*/false);
  fully_free_stale_ = true;
}

std::size_t OctreeMap::clearBox(const VoxelKey& min, const VoxelKey& max, CellChanges* changes) {
  octomap::OcTree kept(tree_.getResolution());
  configureOcTree(kept, sensorModel());
  std::size_t erased = 0;
  forEachOcTreeCell(tree_, [&](const VoxelKey& k, float v) {
    const bool inside = k.x >= min.x && k.y >= min.y && k.z >= min.z && k.x <= max.x &&
                        k.y <= max.y && k.z <= max.z;
    if (!inside) {
      kept.setNodeValue(toOcTreeKey(k), v, /*lazy_eval=*/true);
      return;
    }
    ++erased;
    if (changes != nullptr) changes->push_back({k, 0.0F, false});
  });
  if (erased == 0) return 0;
  for (auto& [block_key, mask] : fully_free_) {
    for (int i = 0; i < block::kVoxels; ++i) {
      const VoxelKey k = block::keyOf(block_key, i);
      if (k.x >= min.x && k.y >= min.y && k.z >= min.z && k.x <= max.x && k.y <= max.y &&
          k.z <= max.z) {
        block::clearBit(mask, i);
      }
    }
  }
  kept.updateInnerOccupancy();
  kept.prune();
  tree_.swapContent(kept);
  return erased;
}

std::optional<float> OctreeMap::logOdds(const VoxelKey& key) const {
  const octomap::OcTreeNode* node = tree_.search(toOcTreeKey(key));
  if (node == nullptr) return std::nullopt;
  return node->getLogOdds();
}

void forEachOcTreeCell(const octomap::OcTree& tree,
                       const std::function<void(const VoxelKey&, float)>& f) {
  const unsigned max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const float value = it->getLogOdds();
    const octomap::OcTreeKey k = it.getKey();
    const unsigned span = 1U << (max_depth - it.getDepth());
    const auto base = [span](std::uint16_t v) { return static_cast<unsigned>(v) & ~(span - 1U); };
    const unsigned x0 = base(k[0]), y0 = base(k[1]), z0 = base(k[2]);
    for (unsigned z = z0; z < z0 + span; ++z) {
      for (unsigned y = y0; y < y0 + span; ++y) {
        for (unsigned x = x0; x < x0 + span; ++x) {
          f(VoxelKey{static_cast<std::uint16_t>(x), static_cast<std::uint16_t>(y),
                     static_cast<std::uint16_t>(z)},
            value);
        }
      }
    }
  }
}

void OctreeMap::forEachKnown(const std::function<void(const VoxelKey&, float)>& f) const {
  forEachOcTreeCell(tree_, f);
}

void OctreeMap::setLogOdds(const VoxelKey& key, float log_odds) {
  tree_.setNodeValue(toOcTreeKey(key), log_odds, /*lazy_eval=*/false);
  noteValue(key, log_odds);
}

void OctreeMap::appendFullyFreeBlocks(const block::BlockBox& box,
                                      std::vector<FullyFreeBlock>& out) const {
  refreshFullyFree();
  for (const auto& [block_key, mask] : fully_free_) {
    if (box.contains(block_key) && block::anyBit(mask)) out.push_back({block_key, mask});
  }
}

void OctreeMap::refreshFullyFree() const {
  if (!fully_free_stale_) return;
  fully_free_.clear();
  forEachOcTreeCell(tree_, [&](const VoxelKey& k, float v) {
    if (sensorModel().isFullyFree(v)) {
      block::setBit(fully_free_[block::blockOf(k)], block::indexOf(k));
    }
  });
  fully_free_stale_ = false;
}

std::size_t OctreeMap::memoryBytes() const {
  constexpr std::size_t kNodeBytes = sizeof(std::uint64_t) + 3 * sizeof(void*);
  return tree_.memoryUsage() + fully_free_.size() * (sizeof(block::BlockMask) + kNodeBytes);
}

void OctreeMap::clear() {
  tree_.clear();
  fully_free_.clear();
  fully_free_stale_ = false;
}

std::size_t OctreeMap::knownCells() const {
  std::size_t n = 0;
  const unsigned max_depth = tree_.getTreeDepth();
  for (auto it = tree_.begin_leafs(), end = tree_.end_leafs(); it != end; ++it) {
    const std::size_t span = std::size_t{1} << (max_depth - it.getDepth());
    n += span * span * span;
  }
  return n;
}

}  // namespace densemap
