#pragma once

#include <octomap/OcTree.h>

#include <filesystem>
#include <memory>

#include "densemap/sim/procedural_scenes.hpp"

namespace densemap {

/// An OctoMap tree as a scene: occupied leaves are solid (e.g. OctoMap's `geb079.bt`).
class OctreeScene final : public Scene {
 public:
  explicit OctreeScene(std::unique_ptr<octomap::OcTree> tree);

  [[nodiscard]] std::optional<double> castRay(const Eigen::Vector3d& origin,
                                              const Eigen::Vector3d& direction,
                                              double max_range_m) const override;
  [[nodiscard]] bool overlapsBox(const Eigen::Vector3d& min,
                                 const Eigen::Vector3d& max) const override;
  [[nodiscard]] Eigen::AlignedBox3d bounds() const override { return bounds_; }
  [[nodiscard]] const octomap::OcTree& tree() const { return *tree_; }

 private:
  std::unique_ptr<octomap::OcTree> tree_;
  Eigen::AlignedBox3d bounds_;
};

/// Loads a .bt/.ot scene; the path is a line along the longest horizontal axis through the
/// known-free cell nearest the map's centre at 1.5 m above the lowest occupied cell.
[[nodiscard]] Expected<SimScene> makeOctreeScene(const std::filesystem::path& file);

}  // namespace densemap
