#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"

namespace densemap::bench {

/// One method on one backend over the whole dataset.
struct RunResult {
  std::string method;
  std::string backend;
  std::string rule = "set";
  int threads = 1;
  double resolution = 0;
  double max_range = -1;
  std::size_t scans = 0;
  std::size_t points = 0;
  std::vector<double> ms_per_scan;
  /// ms_per_scan split by the lanes' turns (--turn): the scans that opened a turn of this lane
  /// (the other lanes ran before them: caches taken, idle worker threads to wake) and the rest.
  std::vector<double> ms_opening_turn, ms_within_turn;
  double total_s = 0;
  bool has_counts = false;  // visits/changed are measured for densemap's own methods only
  bool dense = false;       // a kernel map (visits: kernel-cell updates + free-capsule voxels)
  double visits_per_scan = 0;
  double changed_cells_per_scan = 0;
  /// Distinct cells each scan updates (the floor of an exact update needs each once; the
  /// culling region's cells are skipped, not updated). Visits beyond them are repeats.
  double cells_per_scan = 0;
  // Ray statistics (the dissertation's Tables 2.2-2.3), per scan.
  double rays_per_scan = 0;        // rays traversed; a super ray counts once
  double super_rays_per_scan = 0;  // of which stand for more than one point
  double culled_per_scan = 0;      // traversal steps skipped inside the culling region
  double region_voxels_per_scan = 0;
  double ms_stage[5] = {0, 0, 0, 0, 0};  // mean ms per scan: rays, region, mark, merge, apply
  std::string reference;                 // what diff_cells compares with ("octomap", "raycast")
  long long diff_cells = -1;             // -1: nothing to compare with
  long long diff_cells_vs_octomap = -1;  // -1: no octomap run to compare with
  double speedup_vs_octomap = 0;         // octomap p50 / this p50; 0 when unknown
  std::size_t known_cells = 0;
  std::size_t memory_bytes = 0;
  /// Dense methods: FNV-1a of the evidence (keys, alpha, beta), to compare builds bit for bit.
  std::uint64_t evidence_digest = 0;
  /// The share of the machine's CPU time stolen by the hypervisor while this method's scans
  /// ran (cpu_steal.hpp); negative when unknown.
  double cpu_steal_share = -1;
  /// --esdf: each scan's distance-field update (ms), the cells that changed class per scan,
  /// and the field's bytes after the last scan.
  std::vector<double> esdf_ms;
  double esdf_changes_per_scan = 0;
  std::size_t field_bytes = 0;

  [[nodiscard]] double percentile(double q) const;
  /// The p50 of the scans within turns (not opening one); 0 when there are none.
  [[nodiscard]] double withinTurnP50() const;
  [[nodiscard]] double openingTurnP50() const;
  [[nodiscard]] double pointsPerSecond() const { return total_s > 0 ? points / total_s : 0; }
  /// Wall-clock ns per visit (the mean scan's time over its visits; times `threads` for the
  /// cores' time): what each visit costs, beside how many there are.
  [[nodiscard]] double nsPerVisit() const {
    return scans > 0 && visits_per_scan > 0
               ? total_s * 1e9 / static_cast<double>(scans) / visits_per_scan
               : 0;
  }
};

[[nodiscard]] std::string formatTable(const std::vector<RunResult>& runs);
/// Rays per scan, super rays, points per ray, culled steps and region size per method.
[[nodiscard]] std::string formatRayTable(const std::vector<RunResult>& runs);
/// Each lane's p50 over the scans that opened its turns and over the rest (empty when no lane
/// had more than one turn).
/// --esdf: each lane's distance-field update p50 / p99 beside its integration p50, their
/// ratio, and the field's memory beside the map's (empty when no lane kept a field).
[[nodiscard]] std::string formatFieldTable(const std::vector<RunResult>& runs);
[[nodiscard]] std::string formatTurnTable(const std::vector<RunResult>& runs);
/// The cache probes of a run (cache_probe.hpp): ns a step per vCPU, before and after the lanes
/// (empty: no probe).
struct CacheProbes {
  std::size_t bytes = 0;
  std::vector<double> before, after;
};
[[nodiscard]] std::string formatJson(const std::vector<RunResult>& runs, const std::string& data,
                                     const std::string& machine, const CacheProbes& probes = {});

}  // namespace densemap::bench
