#include "densemap/sim/ground_truth.hpp"

#include <cmath>

#include "densemap/map/octree_map.hpp"

namespace densemap {
namespace {

// OcTree nodes are built directly, top-down. Nodes are never deleted: Debian's OctoMap asserts
// that a deleted node has no child array, so the builder only creates what will hold a leaf.
struct Builder {
  const Scene& scene;
  octomap::OcTree& tree;
  Eigen::AlignedBox3d bounds;  // snapped to voxel boundaries
  unsigned max_depth;
  double min_volume;  // half a voxel: any real overlap with snapped bounds is whole voxels
  float occupied, free;

  void fill(octomap::OcTreeNode* node, unsigned depth, const Eigen::Vector3d& lo,
            const Eigen::Vector3d& hi) {
    const Eigen::Vector3d mid = (lo + hi) / 2;
    for (unsigned i = 0; i < 8; ++i) {
      Eigen::Vector3d clo = lo, chi = mid;
      for (int a = 0; a < 3; ++a) {
        if ((i >> a) & 1U) {  // OctoMap's child index: bit a set = upper half along axis a
          clo[a] = mid[a];
          chi[a] = hi[a];
        }
      }
      const Eigen::AlignedBox3d child(clo, chi);
      if (!bounds.intersects(child) || child.intersection(bounds).volume() < min_volume) continue;
      const bool exists = tree.nodeChildExists(node, i);
      if (depth + 1 == max_depth) {
        octomap::OcTreeNode* leaf =
            exists ? tree.getNodeChild(node, i) : tree.createNodeChild(node, i);
        leaf->setLogOdds(scene.overlapsBox(clo, chi) ? occupied : free);
        continue;
      }
      const bool solid = scene.overlapsBox(clo, chi);
      if (!exists && !solid && bounds.contains(child)) {
        tree.createNodeChild(node, i)->setLogOdds(free);  // the whole octant free: one leaf
        continue;
      }
      octomap::OcTreeNode* c = exists ? tree.getNodeChild(node, i) : tree.createNodeChild(node, i);
      fill(c, depth + 1, clo, chi);
    }
  }
};

}  // namespace

std::unique_ptr<octomap::OcTree> groundTruthOcTree(const Scene& scene, double resolution_m,
                                                   const Eigen::AlignedBox3d& bounds) {
  auto tree = std::make_unique<octomap::OcTree>(resolution_m);
  const SensorModel model;
  configureOcTree(*tree, model);
  const double r = tree->getResolution();
  Eigen::AlignedBox3d snapped;
  for (int a = 0; a < 3; ++a) {
    snapped.min()[a] = std::floor(bounds.min()[a] / r + 1e-9) * r;
    snapped.max()[a] = std::ceil(bounds.max()[a] / r - 1e-9) * r;
  }
  if (snapped.isEmpty() || snapped.volume() <= 0) return tree;
  // The root only comes into being with a first cell: set one inside the bounds (the builder
  // then overwrites it with its true value).
  const Eigen::Vector3d first = snapped.min() + Eigen::Vector3d::Constant(r / 2);
  tree->setNodeValue(octomap::point3d(first.x(), first.y(), first.z()), 0.0F);
  const double half = r * 32768.0;
  Builder b{
      scene,           *tree, snapped, tree->getTreeDepth(), 0.5 * r * r * r, model.clampMax(),
      model.clampMin()};
  b.fill(tree->getRoot(), 0, Eigen::Vector3d::Constant(-half), Eigen::Vector3d::Constant(half));
  tree->updateInnerOccupancy();
  tree->prune();
  return tree;
}

}  // namespace densemap
