#include "densemap/sim/oracle_labels.hpp"

#include <octomap/OcTree.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "densemap/traversal/ray_traversal.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/map/octree_map.hpp"

namespace densemap {

LidarModel denseLidar(const LidarModel& base, int factor) {
  LidarModel dense = base;
  dense.name = base.name + "-x" + std::to_string(factor);
  dense.noise_std_m = 0.0;
  dense.dropout = 0.0;
  if (factor <= 1 || base.elevations_deg.empty()) return dense;
  dense.columns = base.columns * factor;
  dense.elevations_deg.clear();
  const auto& e = base.elevations_deg;
  for (std::size_t b = 0; b + 1 < e.size(); ++b) {
    for (int k = 0; k < factor; ++k) {
      dense.elevations_deg.push_back(e[b] + (e[b + 1] - e[b]) * k / factor);
    }
  }
  dense.elevations_deg.push_back(e.back());
  return dense;
}

void OracleLabeller::add(const PointCloud& points_world, const Point3f& origin_world) {
  tbb::enumerable_thread_specific<ScanUpdate> locals;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points_world.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      ScanUpdate& local = locals.local();
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        const Point3f& p = points_world[i];
                        traverseRay(grid_, origin_world, p,
                                    [&](const VoxelKey& k) { local.markFree(k); });
                        if (const auto key = grid_.pointToKey(p)) local.markOccupied(*key);
                      }
                    });
  for (const ScanUpdate& local : locals) labels_.merge(local);
}

std::vector<LabelledVoxel> OracleLabeller::labels() const {
  std::vector<LabelledVoxel> out;
  labels_.forEachCell([&](const VoxelKey& k, const CellHits& hits) {
    out.push_back({k, hits.occupied > 0});
  });
  return out;
}

Expected<void> OracleLabeller::write(const std::filesystem::path& path) const {
  octomap::OcTree tree(grid_.resolution());
  const SensorModel model;
  configureOcTree(tree, model);
  labels_.forEachCell([&](const VoxelKey& k, const CellHits& hits) {
    tree.setNodeValue(octomap::OcTreeKey(k.x, k.y, k.z),
                      hits.occupied > 0 ? model.clampMax() : model.clampMin(), true);
  });
  tree.updateInnerOccupancy();
  std::ostringstream out;
  if (!writeOctomapBinary(tree, out)) return makeError("cannot serialise oracle labels");
  return writeFileAtomically(path, out.str());
}

std::filesystem::path oracleLabelsPath(const std::filesystem::path& dir, double resolution_m) {
  std::ostringstream name;
  name << "oracle_" << resolution_m << ".bt";
  return dir / name.str();
}

Expected<std::vector<LabelledVoxel>> readOracleLabels(const std::filesystem::path& path,
                                                      double resolution_m) {
  auto bytes = readFileBytes(path);
  if (!bytes) {
    return makeError("no oracle labels: " + bytes.error().message +
                     " (write them with densemap-sim --oracle-factor F --oracle-resolutions R)");
  }
  std::istringstream in(std::move(*bytes), std::ios::binary);
  octomap::OcTree tree(resolution_m);
  if (!tree.readBinary(in)) return makeError(path.string() + ": not a readable OctoMap .bt file");
  if (std::abs(tree.getResolution() - resolution_m) > 1e-9) {
    return makeError(path.string() + " has resolution " + std::to_string(tree.getResolution()) +
                     " m, not " + std::to_string(resolution_m) + " m");
  }
  std::vector<LabelledVoxel> labels;
  const unsigned max_depth = tree.getTreeDepth();
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    const bool occupied = tree.isNodeOccupied(*it);
    // A pruned leaf stands for all the voxels below it (densemap-sim never prunes; a file
    // that expands past the limit is not a label file).
    const unsigned span = 1U << (max_depth - it.getDepth());
    constexpr std::size_t kMaxLabels = std::size_t{1} << 28;
    if (static_cast<std::size_t>(span) * span * span > kMaxLabels - labels.size()) {
      return makeError(path.string() + ": more than 2^28 labelled voxels (pruned leaves?)");
    }
    const octomap::OcTreeKey base = it.getIndexKey();
    for (unsigned z = 0; z < span; ++z) {
      for (unsigned y = 0; y < span; ++y) {
        for (unsigned x = 0; x < span; ++x) {
          labels.push_back({VoxelKey{static_cast<std::uint16_t>(base[0] + x),
                                     static_cast<std::uint16_t>(base[1] + y),
                                     static_cast<std::uint16_t>(base[2] + z)},
                            occupied});
        }
      }
    }
  }
  return labels;
}

}  // namespace densemap
