#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/voxel_grid.hpp"
#include "densemap/kernel/kernel_evidence.hpp"
#include "densemap/kernel/occupancy_samples.hpp"
#include "densemap/geometry/block_layout.hpp"
#include "densemap/map/block_store.hpp"

namespace densemap::kernel {

struct KernelOptions {
  KernelMethod method = KernelMethod::kAkimap;
  double free_step = 0.5;     // m between free samples; segment length for kBgkl, kAkimapRays
  double max_range = -1.0;    // < 0: unlimited
  double prior = 0.001;       // alpha0 = beta0
  double length_scale = 0.2;  // kBgk, kBgkl, kAkimapRays' segments: kernel support radius, m
  double sf2 = 1.0;           // kBgk, kBgkl, kAkimapRays' segments: kernel signal variance
  /// kAkimapRays: free segments stop where a ray comes within `free_margin` of the surface it
  /// hits (m, measured along the surface normal, which AKIMap's kernel shape gives; along the
  /// ray where the neighbourhood is not flat), at most `max_margin` short of the hit; a thin
  /// tip segment continues to `tip_margin` from the surface (< 0: none).
  double free_margin = 0.1;
  double max_margin = 1.0;
  double tip_margin = -1.0;
  double tip_length_scale = 0.1;  // kAkimapRays: the tip's support radius, m
  /// kAkimapRays: > 0: each occupied kernel weighs this at its centre (instead of AKIMap's
  /// |H|^-1/2, which grows as kernels thin), so `sf2` / `occupied_weight` is the balance of
  /// free and occupied evidence whatever the resolution.
  double occupied_weight = -1.0;
  /// kAkimapRays: occupied evidence added to the cell each hit lies in (as a log-odds map's
  /// hit update; 0: none).
  double hit_weight = 0.0;
  /// kAkimapRays: occupied evidence of an isotropic kernel of support radius
  /// `hit_length_voxels` voxels around each hit (so that it reaches the same neighbours at
  /// every resolution), weighing `hit_kernel_weight` at its centre (0: none).
  double hit_kernel_weight = 0.0;
  double hit_length_voxels = 2.0;
  /// kAkimapRays: > 0: each hit kernel (and its cell's hit_weight) is read from a table made
  /// once, its centre moved to the nearest of steps + 1 points per axis across its voxel (i /
  /// steps of a voxel, faces included; 1: the voxel's corners), not evaluated cell by cell
  /// (0: at the hit itself, evaluated). An integer, at most 4; evaluated as with 0 where the
  /// tables would pass 2^18 values (hit_length_voxels over 4 at 4 steps, over 9 at 2).
  double hit_stencil_steps = 0.0;
  /// kAkimapRays: each hit kernel's centre moved this share of the way from the hit (or its
  /// voxel's mean hit) to its voxel's centre, in [0, 1] (0: at the hit; 1: the voxel's centre),
  /// before the tables quantise it. The cell's own evidence does not move.
  double hit_centre_pull = 0.0;
  /// kAkimapRays: the spacing of AKIMap's random free samples that shape the occupied kernels
  /// (<= 0: none, the occupied kernels fitted to the hits alone; 0 in defaults()).
  double negative_step = 0.5;
  // kAkimap, kAkimapRays: the neighbour search box's half-size grows linearly from the voxel size
  // at the sensor to `search_max` at `search_range` (max_range when set).
  double search_max = 0.5;
  double search_range = 30.0;
  /// kAkimap, kAkimapRays: covariance regulariser, a standard deviation (m; at least a voxel) added
  /// on every axis; 0.1 m scores best on the oracle scenes and the la3dm hold-out.
  double min_thickness = 0.1;
  /// kAkimapRays: free evidence by one capsule per ray's free extent and one per tip, rasterised
  /// voxel by voxel (FreeTraversal) instead of a capsule kernel per `free_step` piece
  /// of every ray scheduled through the kernel pairs. Setting free_traversal=0 (or 1).
  bool free_traversal = false;
  /// kAkimapRays with free_traversal: capsules visit the voxels within this fraction of their
  /// radius (the rest of the kernel holds 0.02% of the evidence at 0.85, in 28% of the voxels),
  /// their weight scaled so that a ray leaves the same evidence per metre. (0, 1].
  double free_reach = 1.0;
  /// kAkimapRays with free_traversal: the rays whose hits share a voxel give one free capsule
  /// (to the mean of their free ends, weighing their count) instead of one each; tips stay one
  /// per ray (free_bundles.hpp). A voxel hit by one ray gives that ray's own capsule. Setting
  /// free_bundles=0 (or 1).
  bool free_bundles = false;
  /// kAkimapRays with free_bundles: the edge of the cubes whose hits' rays are bundled, m
  /// (<= the resolution: the map's voxels).
  double free_bundle_m = 0.0;
  /// kAkimapRays with free_bundles: the levels of the tree of bundles above the cubes'
  /// (free_bundles.hpp, freeExtentsTree; 6 in KernelOptions::defaults; 0: each cube's bundle
  /// one capsule from the origin), 0 .. 12.
  double free_bundle_levels = 0.0;
  /// kAkimapRays: one adaptive kernel per voxel of at least `aggregate_min_hits` hits (3 in
  /// KernelOptions::defaults) (at their
  /// mean, weighing their count, fitted to the neighbourhood outside the voxel; its normal sets
  /// its rays' stops) instead of one per hit. Setting aggregate_hits=0 (or 1).
  bool aggregate_hits = false;
  double aggregate_min_hits = 4.0;
  /// kAkimapRays with aggregate_hits: a voxel of at least this many hits but fewer than
  /// aggregate_min_hits keeps a kernel per hit, all of one shape fitted once at their mean to
  /// the neighbourhood outside the voxel (0: a fit per hit).
  double shared_fit_min_hits = 0.0;
  /// kAkimapRays with aggregate_hits: the voxels of hits in one cube of floor(fit_cube_m /
  /// resolution) voxels a side (none below 2) share one fit: the voxel of the most hits is
  /// fitted at its hits' mean (whatever shared_fit_min_hits), and the others take its shape and
  /// normal at their own hits or mean. A surface's shape changes little across a few voxels
  /// (0: a fit per voxel; 0.4 in KernelOptions::defaults).
  double fit_cube_m = 0.0;
  std::uint64_t seed = 1;
  /// The plain path, for tests: visit every cell of each kernel's bounding box and evaluate it
  /// there by Kernel::at, instead of only each row's stretch that the kernel can reach (and
  /// isotropic point kernels from per-axis squared offsets): the same results, bit for bit.
  bool whole_boxes = false;

  /// The published settings of each method (la3dm's for the baselines); for kAkimapRays
  /// densemap's own (kernel_options.cpp says how they were chosen).
  [[nodiscard]] static KernelOptions defaults(KernelMethod method);
};

/// Applies "NAME=VALUE" settings to `options`: any double field above by its name (free_step,
/// length_scale, sf2, prior, free_margin, max_margin, tip_margin, tip_length_scale,
/// occupied_weight, hit_weight, hit_kernel_weight, hit_length_voxels, hit_stencil_steps,
/// hit_centre_pull,
/// negative_step, search_max, search_range, min_thickness, aggregate_min_hits,
/// shared_fit_min_hits, fit_cube_m, free_reach, free_bundle_m, free_bundle_levels), and
/// free_traversal=0|1, aggregate_hits=0|1, free_bundles=0|1; errors name the setting.
[[nodiscard]] Expected<void> applySettings(KernelOptions& options,
                                           const std::vector<std::string>& settings);

struct KernelScanStats {
  std::size_t samples = 0;
  std::size_t free_visits = 0;   // (capsule, voxel) pairs with free evidence (free_traversal)
  std::size_t cell_updates = 0;  // (cell, kernel) pairs with a non-zero contribution
  /// Stage times, ms: samples, occupied kernels (fitting), occupied accumulation (scheduling and
  /// summing the kernels), free evidence (capsules), applying the free sums to the blocks.
  double ms_samples = 0, ms_kernels = 0, ms_occupied = 0, ms_free = 0, ms_apply = 0;
};

/// A dense occupancy map by Bayesian kernel inference: per cell Beta(alpha, beta), with the
/// kernels of each scan's samples accumulated into alpha (occupied) and beta (free), Eq. 3.8-3.9.
/// The result depends only on the scans and the seed, never on the thread count: each 8^3
/// block sums its kernels in sample order.
class FreeTraversal;

class KernelMap {
 public:
  /// `store`: where the evidence lives, a block per entry (BlockStore::evidence): a GridMap's
  /// store, so that the evidence and the log-odds it publishes share one index and a block the
  /// grid drops loses both; null: a store of its own (offline).
  KernelMap(double resolution_m, const KernelOptions& options, BlockStore* store = nullptr);
  ~KernelMap();
  KernelMap(KernelMap&&) noexcept;
  KernelMap& operator=(KernelMap&&) noexcept;

  [[nodiscard]] const VoxelGrid& grid() const { return grid_; }
  [[nodiscard]] const KernelOptions& options() const { return options_; }

  /// Integrates one scan (finite points, world frame) taken from `origin_world`. When `touched`
  /// is given, the cells this scan's kernels reached are appended to it, a block each, in
  /// block-key order.
  KernelScanStats integrate(const PointCloud& points_world, const Point3f& origin_world,
                            std::vector<BlockCells>* touched = nullptr);
  /// Forgets a cell's evidence (it becomes unknown).
  void erase(const VoxelKey& key);
  /// Drops the evidence of every block whose centre (block::centreOf) `keep` refuses, with its
  /// memory. Returns the blocks dropped. (A map in a GridMap's store loses a block's evidence
  /// when the grid evicts the block: GridMap::evictBlocks.)
  std::size_t evictBlocks(const std::function<bool(const Point3f&)>& keep);

  /// alpha / (alpha + beta); std::nullopt where no kernel reached the cell (unknown).
  [[nodiscard]] std::optional<double> probability(const VoxelKey& key) const;
  /// The log-odds log(p / (1 - p)) of the cells of `cells` in block `block_key` (0 where
  /// unknown, p = 0.5), into log_odds[cell]. Safe from parallel tasks between scans.
  void blockLogOdds(std::uint64_t block_key, const block::BlockMask& cells,
                    std::array<float, block::kVoxels>& log_odds) const;
  void forEachKnown(const std::function<void(const VoxelKey&, double)>& f) const;
  [[nodiscard]] std::size_t knownCells() const;
  /// Bytes held: the evidence blocks when the store is its own (a GridMap's counts them in its
  /// own memoryBytes) and the per-scan buffers held (none between scans: each stage's are
  /// released when it ends).
  [[nodiscard]] std::size_t memoryBytes() const;
  [[nodiscard]] std::size_t scans() const { return scans_; }

  /// A copy of the evidence (snapshots).
  [[nodiscard]] KernelEvidence evidence() const;
  /// Replaces the map's evidence with `evidence`: an error (and the map unchanged) when it is
  /// another method's or resolution's, its arrays differ in length, or a value is not finite
  /// and >= 0. Restored, the map integrates its next scan exactly as the one saved would.
  [[nodiscard]] Expected<void> restore(const KernelEvidence& evidence);

 private:
  /// The evidence of `block_key`, or null (writer).
  [[nodiscard]] const BlockEvidence* find(std::uint64_t block_key) const;
  /// Calls f(block_key, evidence) for every block with evidence, in block-key order.
  template <typename F>
  void forEachBlock(F&& f) const;

  // integrate()'s stages, in order; they pass their results through the scan buffers.
  void drawSamples(const PointCloud& points_world, const Point3f& origin_world);
  void fitKernels(const PointCloud& points_world, const Point3f& origin_world);
  void sortKernelPairs();
  std::size_t accumulateKernels(std::vector<std::pair<std::uint64_t, block::BlockMask>>* reached);
  void applyFree(std::vector<std::pair<std::uint64_t, block::BlockMask>>* reached);
  static void mergeReached(std::vector<std::pair<std::uint64_t, block::BlockMask>>& reached,
                           std::vector<BlockCells>& touched);

  VoxelGrid grid_;
  KernelOptions options_;
  std::unique_ptr<BlockStore> own_store_;  // when no store was given
  BlockStore* store_;                      // the evidence's store
  std::size_t scans_ = 0;
  std::unique_ptr<FreeTraversal> free_;     // its buffers
  std::vector<Sample> samples_, segments_;  // per-scan buffers (see Scratch)
  struct Scratch;                           // the other per-scan buffers (kernel_map.cpp)
  std::unique_ptr<Scratch> scratch_;
};

}  // namespace densemap::kernel
