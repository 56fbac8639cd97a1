#include "map_kind.hpp"

#include <array>
#include <chrono>
#include <cmath>
#include <vector>

#include "densemap/geometry/stopwatch.hpp"

namespace densemap {

MapKind::MapKind(std::unique_ptr<OccupancyMap> map) : map_(std::move(map)) {
  readable_ = dynamic_cast<GridMap*>(map_.get());
  if (readable_ == nullptr) {
    mirror_ = std::make_unique<GridMap>(map_->resolution(), map_->sensorModel());
    mirror_->setRunner(map_->runner());
    map_->forEachKnown([this](const VoxelKey& k, float v) { mirror_->setLogOdds(k, v); });
    readable_ = mirror_.get();
  }
}

MapKind::~MapKind() = default;

Expected<std::string> MapKind::command(const Command& command, CellChanges& changes) {
  Expected<std::string> outcome = command(*map_, changes);
  forget(changes);
  return outcome;
}

void MapKind::beforePublish(const CellChanges& changes) {
  if (mirror_) mirror_->applyChanges(changes);
}

std::size_t MapKind::ownBytes() const { return mirror_ ? map_->memoryBytes() : 0; }

EvictStats MapKind::evict(const Keep& keep, CellChanges* changes) {
  return readable_->evictBlocks(keep, changes);
}

namespace {

class LogOddsKind final : public MapKind {
 public:
  LogOddsKind(std::unique_ptr<OccupancyMap> map, const IntegratorOptions& options)
      : MapKind(std::move(map)), integrator_(options) {}

  ScanStats integrate(const PointCloud& points_world, const Point3f& origin,
                      CellChanges* changes) override {
    return integrator_.integrate(map(), points_world, origin, changes);
  }

  std::span<const RayEnd> rayEnds() const override { return integrator_.rayEnds(); }

  Expected<void> restore(const kernel::KernelEvidence& evidence) override {
    return makeError("the map kind is log_odds: kernel evidence of " +
                     std::string(kernel::kernelMethodName(evidence.method)) + " has no place");
  }

  void warmUp(double max_range_m) override {
    // A sparse fan (16 x 256 rays) at 90% of the max range (50 m when unlimited), +-3 deg
    // about the horizon: the rays' box (which sizes the dense free marks) is as wide as a real
    // scan's, and the blocks the rays touch size the per-worker update tables (a smaller fan
    // sizes them too small to spare the first scans their allocations).
    const float range = 0.9F * static_cast<float>(max_range_m > 0 ? max_range_m : 50.0);
    PointCloud points;
    points.reserve(16 * 256);
    for (int beam = 0; beam < 16; ++beam) {
      const float elevation = (-3.0F + 6.0F * static_cast<float>(beam) / 15.0F) * 0.0174533F;
      for (int col = 0; col < 256; ++col) {
        const float azimuth = 6.2831853F * static_cast<float>(col) / 256.0F;
        points.emplace_back(range * std::cos(elevation) * std::cos(azimuth),
                            range * std::cos(elevation) * std::sin(azimuth),
                            range * std::sin(elevation));
      }
    }
    GridMap scratch(map().resolution(), map().sensorModel());
    // Twice: each TBB worker has its own buffers, and one pass may not reach every worker.
    for (int pass = 0; pass < 2; ++pass) {
      (void)integrator_.integrate(scratch, points, Point3f::Zero());
    }
  }

 private:
  Integrator integrator_;
};

class KernelKind final : public MapKind {
 public:
  KernelKind(std::unique_ptr<OccupancyMap> map, const kernel::KernelOptions& options)
      : MapKind(std::move(map)), kernel_(published().resolution(), options, evidenceStore()) {}

  ScanStats integrate(const PointCloud& points_world, const Point3f& origin,
                      CellChanges* changes) override {
    auto t0 = std::chrono::steady_clock::now();
    std::vector<BlockCells> touched;
    kernel_.integrate(points_world, origin, &touched);
    ScanStats stats;
    stats.points = points_world.size();
    stats.rays = points_world.size();
    stats.ms_mark = msSince(t0);
    // The published map follows the evidence of the cells this scan reached: block by block,
    // in parallel, on the grid; cell by cell on another backend.
    const auto values = [this](std::uint64_t block_key, const block::BlockMask& cells,
                               std::array<float, block::kVoxels>& log_odds) {
      kernel_.blockLogOdds(block_key, cells, log_odds);
    };
    if (auto* grid = dynamic_cast<GridMap*>(&map())) {
      const ApplyStats applied = grid->assignBlocks(touched, values, changes);
      stats.updated = applied.updated_cells;
      stats.changed = applied.changed_cells;
    } else {
      std::array<float, block::kVoxels> log_odds{};
      for (const BlockCells& b : touched) {
        values(b.key, b.cells, log_odds);
        block::forEachSetBit(b.cells, [&](int cell) {
          const VoxelKey key = block::keyOf(b.key, cell);
          ++stats.updated;
          if (map().logOdds(key) != log_odds[cell]) {
            map().setLogOdds(key, log_odds[cell]);
            ++stats.changed;
            if (changes != nullptr) changes->push_back({key, log_odds[cell], true});
          }
        });
      }
    }
    stats.ms_apply = msSince(t0);
    return stats;
  }

  std::optional<kernel::KernelEvidence> evidence() const override { return kernel_.evidence(); }

  Expected<void> restore(const kernel::KernelEvidence& evidence) override {
    return kernel_.restore(evidence);
  }

 protected:
  void forget(const CellChanges& changes) override {
    for (const CellChange& c : changes) {
      if (!c.known) kernel_.erase(c.key);
    }
  }

 private:
  /// The grid's store when the map is the grid (canEvict: eviction drops a block's evidence
  /// with its cells), else none (the kernel map's own, beside an octree).
  BlockStore* evidenceStore() {
    auto* grid = dynamic_cast<GridMap*>(&map());
    return grid != nullptr ? &grid->writerStore() : nullptr;
  }

  kernel::KernelMap kernel_;
};

}  // namespace

std::unique_ptr<MapKind> makeLogOddsKind(std::unique_ptr<OccupancyMap> map,
                                         const IntegratorOptions& integrator) {
  return std::make_unique<LogOddsKind>(std::move(map), integrator);
}

std::unique_ptr<MapKind> makeKernelKind(std::unique_ptr<OccupancyMap> map,
                                        const kernel::KernelOptions& options) {
  return std::make_unique<KernelKind>(std::move(map), options);
}

}  // namespace densemap
