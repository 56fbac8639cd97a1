#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "densemap/map/block_layout.hpp"

namespace densemap::kernel {

/// One engine, three configurations (dissertation Ch. 3 and its baselines).
enum class KernelMethod {
  kAkimap,  // adaptive anisotropic kernels, random free samples
  kBgk,     // BGKOctoMap: isotropic kernels on points, regular free points
  kBgkl,    // BGKOctoMap-L: isotropic kernels on points, free ray segments
};

[[nodiscard]] std::string_view kernelMethodName(KernelMethod method);
[[nodiscard]] Expected<KernelMethod> parseKernelMethod(std::string_view name);

struct KernelOptions {
  KernelMethod method = KernelMethod::kAkimap;
  double free_step = 0.5;     // m between free samples; segment length for kBgkl
  double max_range = -1.0;    // < 0: unlimited
  double prior = 0.001;       // alpha0 = beta0
  double length_scale = 0.2;  // kBgk, kBgkl: kernel support radius, m
  double sf2 = 1.0;           // kBgk, kBgkl: kernel signal variance
  // kAkimap: the neighbour search box's half-size grows linearly from the voxel size at the
  // sensor to `search_max` at `search_range` (max_range when set).
  double search_max = 0.5;
  double search_range = 30.0;
  /// kAkimap: covariance regulariser, a standard deviation (m; at least a voxel) added on every
  /// axis. 0.1 m measured best of {1, 2, 3} voxels at 0.1 m and 0.05 m on the oracle scenes
  /// and the la3dm hold-out (issue 5 note).
  double min_thickness = 0.1;
  std::uint64_t seed = 1;

  /// The published settings of each method (la3dm's for the baselines).
  [[nodiscard]] static KernelOptions defaults(KernelMethod method);
};

struct KernelScanStats {
  std::size_t samples = 0;
  std::size_t cell_updates = 0;  // (cell, kernel) pairs with a non-zero contribution
  double ms_samples = 0, ms_bandwidth = 0, ms_accumulate = 0;
};

/// A dense occupancy map by Bayesian kernel inference: per cell Beta(alpha, beta), with the
/// kernels of each scan's samples accumulated into alpha (occupied) and beta (free), Eq. 3.8-3.9.
/// The result depends only on the scans and the seed, never on the thread count: each 8^3
/// block sums its kernels in sample order.
class KernelMap {
 public:
  KernelMap(double resolution_m, const KernelOptions& options);

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  [[nodiscard]] const KernelOptions& options() const { return options_; }

  /// Integrates one scan (finite points, world frame) taken from `origin_world`. When `touched`
  /// is given, the cells this scan's kernels reached are appended to it (block by block, in
  /// block-key order).
  KernelScanStats integrate(const PointCloud& points_world, const Point3f& origin_world,
                            std::vector<VoxelKey>* touched = nullptr);
  /// Forgets a cell's evidence (it becomes unknown).
  void erase(const VoxelKey& key);

  /// alpha / (alpha + beta); std::nullopt where no kernel reached the cell (unknown).
  [[nodiscard]] std::optional<double> probability(const VoxelKey& key) const;
  void forEachKnown(const std::function<void(const VoxelKey&, double)>& f) const;
  [[nodiscard]] std::size_t knownCells() const;
  [[nodiscard]] std::size_t scans() const { return scans_; }

 private:
  struct Block {
    std::array<double, block::kVoxels> alpha{};
    std::array<double, block::kVoxels> beta{};
    block::BlockMask known{};
  };

  VoxelGrid grid_;
  KernelOptions options_;
  std::unordered_map<std::uint64_t, Block> blocks_;
  std::size_t scans_ = 0;
};

}  // namespace densemap::kernel
