#pragma once

#include <tbb/enumerable_thread_specific.h>

#include <cstddef>
#include <limits>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"
#include "densemap/map/occupancy_map.hpp"
#include "densemap/raycast/culling_region.hpp"
#include "densemap/raycast/ray_marking.hpp"
#include "densemap/raycast/super_rays.hpp"

namespace densemap {

/// How a scan's rays reach the map. All methods give the same map (docs/architecture.md, exactness
/// contract), under either UpdateRule.
/// - kRaycast: every ray traversed on its own (the default: the fastest where measured).
/// - kSuperRay: rays grouped into super rays first (SuperRayBuilder).
/// - kCulling: traversals skip the scan's culling region (CullingRegion).
/// - kSuperRayCulling: both.
enum class IntegrationMethod { kRaycast, kSuperRay, kCulling, kSuperRayCulling };

[[nodiscard]] std::string_view methodName(IntegrationMethod method);
/// "raycast", "superray", "culling" or "superray+culling".
[[nodiscard]] Expected<IntegrationMethod> parseIntegrationMethod(std::string_view name);

struct IntegratorOptions {
  IntegrationMethod method = IntegrationMethod::kRaycast;
  UpdateRule rule = UpdateRule::kSet;
  /// Rays longer than this are cut and their end is not occupied; < 0 means unlimited
  /// (OctoMap's convention).
  double max_range_m = -1.0;
  /// End voxels with fewer rays are not grouped (the dissertation's k, Sec. 2.4.3).
  std::size_t superray_min_points = 20;
  /// The culling region's box is shrunk around the sensor to at most this many voxels
  /// (one bit each: 2^27 voxels = 16 MiB).
  std::size_t culling_max_voxels = std::size_t{1} << 27;
  /// Under UpdateRule::kSet each worker marks free voxels in a dense array of 8^3 blocks over
  /// the scan's box (64 bytes per block) when the box has at most this many blocks; 0: never.
  std::size_t dense_marks_max_blocks = std::size_t{1} << 21;
  /// With a culling region under UpdateRule::kSet (and dense marks sharing its frame), the
  /// rays are marked in levels: first those whose index is a multiple of grow_strides[0], then
  /// of grow_strides[1] (not already marked), ..., then the rest; after each level the region
  /// grows by the voxels marked so far (CullingRegion::grow), so later rays stop sooner.
  /// Each ray is marked once, at the first level whose stride divides its index (strides <= 1
  /// are ignored); empty: one level (the region from the map only).
  std::vector<std::size_t> grow_strides{16};
  /// A growing region's box is shrunk around the sensor to at most this many voxels: each
  /// growth copies, loads and sweeps it (one bit a voxel: 2 MiB at 2^24).
  std::size_t grow_max_voxels = std::size_t{1} << 24;
  /// Growth continues while the last growing scan's later levels (after the first) had at
  /// least this share of their traversal steps culled; below it, only every
  /// grow_probe_every-th scan grows (to measure again).
  double grow_min_share = 0.25;
  std::size_t grow_probe_every = 8;
  /// With dense marks, the rays' walks (forward ones, or backward ones with a culling region
  /// sharing their box's frame) are queued and walked several at a time where the processor
  /// has the lanes (DenseMarks::markQueued and markQueuedBack: eight side by side with AVX-512,
  /// four with AVX2), else one at a time as they come, as with false (a
  /// queue walked one walk at a time costs more than walking as they come: measured); the
  /// same marks either way.
  bool queue_walks = true;
  /// How queued walks are walked (DenseMarks::WalkKernel; the same marks with each).
  DenseMarks::WalkKernel walk_kernel = DenseMarks::WalkKernel::kBest;
};

/// What integrating one scan did; the benchmark's per-scan figures.
struct ScanStats {
  std::size_t points = 0;
  std::size_t rays = 0;           // rays traversed (super rays count once)
  std::size_t super_rays = 0;     // of which stand for more than one point
  std::size_t visits = 0;         // cells marked while traversing rays (with repeats)
  std::size_t culled = 0;         // traversal steps skipped inside the culling region
  std::size_t region_voxels = 0;  // size of the culling region
  std::size_t updated = 0;        // distinct cells updated
  std::size_t changed = 0;        // cells whose log-odds changed or that became known
  // Wall time of each stage, ms: rays (+ super rays), culling region, marking, merging the
  // workers' update sets, applying to the map. The region is built alongside the super rays:
  // ms_region is its own build time and ms_rays the rest of that span.
  double ms_rays = 0, ms_region = 0, ms_mark = 0, ms_merge = 0, ms_apply = 0;
};

/// Integrates scans into a map: rays (optionally grouped into super rays) are marked into
/// one update set per TBB worker (optionally skipping the culling region), merged (bitwise OR,
/// integer sums), then applied once, so the result is the same for any thread count.
/// Equal to OctoMap's `insertPointCloud(cloud, origin, max_range, false, false)` cell for cell
/// under UpdateRule::kSet. Runs in the caller's task arena.
/// Thread-safety: one integrate() at a time per integrator (it reuses per-worker buffers).
class Integrator {
 public:
  explicit Integrator(const IntegratorOptions& options = {})
      : options_(options), locals_([rule = options.rule] {
          return Local{ScanUpdate(rule), {}, {}, {}, false, {}, {}};
        }) {}

  [[nodiscard]] const IntegratorOptions& options() const { return options_; }

  /// Integrates one scan; appends the cells it changed to `changes` when given.
  ScanStats integrate(OccupancyMap& map, const PointCloud& points_world,
                      const Point3f& origin_world, CellChanges* changes = nullptr);

  /// Builds the scan's update set (against `map`'s current state) without applying it.
  ScanStats computeUpdate(const OccupancyMap& map, const PointCloud& points_world,
                          const Point3f& origin_world, ScanUpdate& update);

  /// The last scan's ray ends, one per point in its order (valid until the next scan).
  [[nodiscard]] std::span<const RayEnd> rayEnds() const { return rays_; }

 private:
  struct Local {
    ScanUpdate update;
    MarkCounts counts;
    BackwardScratch scratch;
    DenseMarks dense;
    bool dense_ok = false;              // `dense` covers this scan's box
    std::vector<std::uint32_t> handed;  // rays whose queued walks were handed over
    std::vector<std::uint32_t> ids;     // a range's rays, for the queued walks
  };
  struct ScanPlan;
  // computeUpdate's stages, in order.
  /// The rays' ends into rays_; the box of their end voxels (none without a valid end).
  std::optional<KeyBox> findRayEnds(const VoxelGrid& grid, const PointCloud& points_world,
                                    const Point3f& origin_world);
  /// The scan's box, stages and levels (and the region's seeds, hit_).
  ScanPlan planScan(const VoxelGrid& grid, const Point3f& origin_world,
                    const std::optional<KeyBox>& ends);
  /// Super rays and the culling region; the region the walks may skip, or null.
  const CullingRegion* groupAndCull(const OccupancyMap& map, const Point3f& origin_world,
                                    const ScanPlan& plan, ScanStats& stats);
  /// Marks one level's rays into the workers' marks.
  void markLevel(const VoxelGrid& grid, const Point3f& origin_world, const ScanPlan& plan,
                 std::size_t level, const CullingRegion* region);
  /// Grows the region by the voxels the workers marked free (adding the growth's time to
  /// `ms_grow`); the region, or null when empty.
  const CullingRegion* growRegion(double& ms_grow);
  /// The workers' marks into `update`; their counts into `stats`.
  void mergeInto(ScanUpdate& update, ScanStats& stats);
  IntegratorOptions options_;
  std::vector<RayEnd> rays_;
  std::vector<VoxelKey> hit_;
  std::vector<FullyFreeBlock> covered_;
  std::vector<DenseMarks*> others_;  // the workers' dense marks after the first, to flush
  SuperRayBuilder super_rays_;
  CullingRegion region_;
  tbb::enumerable_thread_specific<Local> locals_;
  ScanUpdate merged_;
  // The culled share of the last growing scan's later levels (none yet: grow).
  double grow_share_ = std::numeric_limits<double>::infinity();
  std::size_t scans_since_grown_ = 0;
};

}  // namespace densemap
