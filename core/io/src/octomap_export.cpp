#include "densemap/io/octomap_export.hpp"

#include <octomap/OcTree.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/map/octree_map.hpp"

namespace densemap {

bool writeOctomapBinary(const octomap::OcTree& tree, std::ostream& out) {
  // AbstractOccupancyOcTree::writeBinaryConst's header (binaryFileHeader is protected), then
  // the same node data.
  out << "# Octomap OcTree binary file\n"
      << "# (feel free to add / change comments, but leave the first line as it is!)\n#\n";
  out << "id " << tree.getTreeType() << '\n';
  out << "size " << tree.size() << '\n';
  out << "res " << tree.getResolution() << '\n';
  out << "data\n";
  tree.writeBinaryData(out);
  return out.good();
}

Expected<void> exportOctomap(const OccupancyMap& map, const std::filesystem::path& file) {
  const std::string ext = file.extension().string();
  if (ext != ".bt" && ext != ".ot") return fileError(file, "export needs a .bt or .ot name");
  std::unique_ptr<octomap::OcTree> copy;
  const octomap::OcTree* tree = nullptr;
  const bool binary = ext == ".bt";
  const auto* octree = dynamic_cast<const OctreeMap*>(&map);
  if (octree != nullptr && !binary) {
    tree = &octree->tree();
  } else {
    copy = std::make_unique<octomap::OcTree>(map.resolution());
    configureOcTree(*copy, map.sensorModel());
    // OcTree::setNodeValue clamps to the tree's thresholds. A log-odds map never leaves them,
    // but a kernel map's logit(p) can: widen them so that every value is written as it is (the
    // thresholds are not part of the file).
    float lowest = 0.0F, highest = 0.0F;
    map.forEachKnown([&](const VoxelKey&, float v) {
      lowest = std::min(lowest, v);
      highest = std::max(highest, v);
    });
    const auto probability = [](double log_odds) { return 1.0 / (1.0 + std::exp(-log_odds)); };
    if (lowest < copy->getClampingThresMinLog()) {
      copy->setClampingThresMin(probability(lowest - 1.0));
    }
    if (highest > copy->getClampingThresMaxLog()) {
      copy->setClampingThresMax(probability(highest + 1.0));
    }
    map.forEachKnown([&](const VoxelKey& k, float v) {
      copy->setNodeValue(octomap::OcTreeKey(k.x, k.y, k.z), binary ? octomapClassValue(v) : v,
                         /*lazy_eval=*/true);
    });
    copy->updateInnerOccupancy();
    copy->prune();
    tree = copy.get();
  }
  std::ostringstream out;
  const bool ok = ext == ".bt" ? writeOctomapBinary(*tree, out) : tree->write(out);
  if (!ok) return fileError(file, "OctoMap failed to serialise the tree");
  return writeFileAtomically(file, out.str());
}

Expected<std::unique_ptr<OccupancyMap>> importOctomap(const std::filesystem::path& file,
                                                      Backend backend) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  std::unique_ptr<octomap::OcTree> tree;
  std::istringstream in(*bytes);
  if (file.extension() == ".bt") {
    tree = std::make_unique<octomap::OcTree>(0.1);
    if (!tree->readBinary(in) || tree->getResolution() <= 0.0) {
      return fileError(file, "not a readable OctoMap binary (.bt) file");
    }
  } else {
    std::unique_ptr<octomap::AbstractOcTree> abstract(octomap::AbstractOcTree::read(in));
    auto* as_octree = dynamic_cast<octomap::OcTree*>(abstract.get());
    if (as_octree == nullptr) return fileError(file, "not a readable OctoMap OcTree (.ot) file");
    abstract.release();
    tree.reset(as_octree);
  }
  auto map = makeMap(backend, tree->getResolution());
  if (!map) return fileError(file, map.error().message);
  forEachOcTreeCell(*tree, [&](const VoxelKey& k, float v) { (*map)->setLogOdds(k, v); });
  return std::move(*map);
}

}  // namespace densemap
