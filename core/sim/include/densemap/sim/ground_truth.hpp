#pragma once

#include <octomap/OcTree.h>

#include <memory>

#include "densemap/sim/scene.hpp"

namespace densemap {

/// The scene's true occupancy inside `bounds` at `resolution_m`, as an OcTree: a voxel is
/// occupied (log-odds clamp max) when a solid overlaps it, free (clamp min) otherwise; voxels
/// outside `bounds` stay unknown. Built top-down, so free space costs one node per empty
/// octant rather than one per voxel.
[[nodiscard]] std::unique_ptr<octomap::OcTree> groundTruthOcTree(const Scene& scene,
                                                                 double resolution_m,
                                                                 const Eigen::AlignedBox3d& bounds);

}  // namespace densemap
