#include "densemap/sim/octree_scene.hpp"

#include <limits>
#include <sstream>

#include "densemap/io/file_bytes.hpp"

namespace densemap {
namespace {

octomap::point3d toPoint(const Eigen::Vector3d& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

}  // namespace

OctreeScene::OctreeScene(std::unique_ptr<octomap::OcTree> tree) : tree_(std::move(tree)) {
  double x0, y0, z0, x1, y1, z1;
  tree_->getMetricMin(x0, y0, z0);
  tree_->getMetricMax(x1, y1, z1);
  bounds_ = Eigen::AlignedBox3d(Eigen::Vector3d(x0, y0, z0), Eigen::Vector3d(x1, y1, z1));
}

std::optional<double> OctreeScene::castRay(const Eigen::Vector3d& origin,
                                           const Eigen::Vector3d& direction,
                                           double max_range_m) const {
  octomap::point3d hit_center;
  if (!tree_->castRay(toPoint(origin), toPoint(direction), hit_center,
                      /*ignoreUnknownCells=*/true, max_range_m)) {
    return std::nullopt;
  }
  // The surface, not the voxel centre: where the ray enters the hit voxel.
  octomap::point3d entry;
  if (tree_->getRayIntersection(toPoint(origin), toPoint(direction), hit_center, entry)) {
    const double d = (entry - toPoint(origin)).norm();
    if (d <= max_range_m) return d;
  }
  const double d = (hit_center - toPoint(origin)).norm();
  return d <= max_range_m ? std::optional<double>(d) : std::nullopt;
}

bool OctreeScene::overlapsBox(const Eigen::Vector3d& min, const Eigen::Vector3d& max) const {
  for (auto it = tree_->begin_leafs_bbx(toPoint(min), toPoint(max)), end = tree_->end_leafs_bbx();
       it != end; ++it) {
    if (tree_->isNodeOccupied(*it)) return true;
  }
  return false;
}

Expected<SimScene> makeOctreeScene(const std::filesystem::path& file) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  auto tree = std::make_unique<octomap::OcTree>(0.1);
  std::istringstream in(*bytes);
  const bool ok = file.extension() == ".ot" ? false : tree->readBinary(in) && tree->size() > 0;
  if (!ok) return fileError(file, "not a readable OctoMap binary (.bt) scene");
  auto scene = std::make_unique<OctreeScene>(std::move(tree));
  const octomap::OcTree& t = scene->tree();
  const Eigen::AlignedBox3d box = scene->bounds();

  double floor_z = std::numeric_limits<double>::infinity();
  for (auto it = t.begin_leafs(), end = t.end_leafs(); it != end; ++it) {
    if (t.isNodeOccupied(*it)) floor_z = std::min(floor_z, static_cast<double>(it.getZ()));
  }
  const Eigen::Vector3d target(box.center().x(), box.center().y(), floor_z + 1.5);
  Eigen::Vector3d start = target;
  double best = std::numeric_limits<double>::infinity();
  for (auto it = t.begin_leafs(), end = t.end_leafs(); it != end; ++it) {
    if (t.isNodeOccupied(*it) || it.getSize() > 4 * t.getResolution()) continue;
    const Eigen::Vector3d c(it.getX(), it.getY(), it.getZ());
    const double d = (c - target).squaredNorm();
    if (d < best) {
      best = d;
      start = c;
    }
  }
  const Eigen::Vector3d axis =
      box.sizes().x() >= box.sizes().y() ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  SimScene out{file.filename().string(), std::move(scene), {}};
  // Walk both ways until a wall is within 0.5 m, at most 6 m each way.
  auto reach = [&](const Eigen::Vector3d& dir) {
    const auto hit = out.scene->castRay(start, dir, 6.0);
    return start + dir * std::max(0.0, (hit ? *hit : 6.0) - 0.5);
  };
  out.waypoints = {reach(-axis), reach(axis)};
  return out;
}

}  // namespace densemap
