#include "densemap/sim/sequence.hpp"

#include <algorithm>
#include <numeric>
#include <random>
#include <sstream>

#include "densemap/io/dataset_writer.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/octomap_export.hpp"
#include "densemap/sim/ground_truth.hpp"
#include "densemap/sim/lidar_simulator.hpp"
#include "densemap/sim/octree_scene.hpp"
#include "densemap/sim/oracle_labels.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/trajectory.hpp"
#include "densemap/sim/walker_scene.hpp"

namespace densemap {
namespace {

Expected<LidarModel> lidarFor(const SequenceOptions& o) {
  auto lidar = lidarPreset(o.sensor);
  if (!lidar) return lidar;
  if (o.columns != 0) lidar->columns = o.columns;
  if (o.beams != 0) {
    if (o.beams < 2 || o.beams > 4096 || !(o.top_deg > o.bottom_deg)) {
      return makeError("beams must be in 2..4096 with top_deg > bottom_deg");
    }
    lidar->elevations_deg.clear();
    for (int b = 0; b < o.beams; ++b) {
      lidar->elevations_deg.push_back(o.top_deg - b * (o.top_deg - o.bottom_deg) / (o.beams - 1));
    }
  }
  if (o.max_range_m != 0.0) lidar->max_range_m = o.max_range_m;
  lidar->noise_std_m = o.noise_std_m;
  lidar->dropout = o.dropout;
  if (auto ok = lidar->validate(); !ok) return std::unexpected(ok.error());
  return lidar;
}

std::string describe(const SequenceOptions& o, const LidarModel& lidar) {
  std::ostringstream s;
  s << "scene " << o.scene << "\nsensor " << o.sensor << "\nbeams " << lidar.beams() << "\ncolumns "
    << lidar.columns << "\nmax_range_m " << lidar.max_range_m << "\nnoise_std_m " << o.noise_std_m
    << "\ndropout " << o.dropout << "\nscans " << o.scans << "\nseed " << o.seed
    << "\nelevations_deg " << lidar.elevations_deg.front() << ' ' << lidar.elevations_deg.back()
    << "\nground_truth_resolution_m " << o.ground_truth_resolution_m << "\npoints_per_scan "
    << o.points_per_scan << "\noracle_factor " << o.oracle_factor << "\nwalkers " << o.walkers
    << "\noracle_resolutions";
  for (const double r : o.oracle_resolutions) s << ' ' << r;
  s << "\n";
  return s.str();
}

/// Keeps `n` of the scan's points, chosen at random (seeded per scan), in their order.
void subsample(Scan& scan, std::size_t n, std::uint64_t seed) {
  if (n == 0 || scan.points.size() <= n) return;
  std::vector<std::size_t> index(scan.points.size());
  std::iota(index.begin(), index.end(), 0);
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ULL + scan.id);
  for (std::size_t i = 0; i < n; ++i) {  // partial Fisher-Yates
    std::uniform_int_distribution<std::size_t> pick(i, index.size() - 1);
    std::swap(index[i], index[pick(rng)]);
  }
  index.resize(n);
  std::sort(index.begin(), index.end());
  PointCloud points;
  std::vector<float> intensities;
  for (const std::size_t i : index) {
    points.push_back(scan.points[i]);
    if (!scan.intensities.empty()) intensities.push_back(scan.intensities[i]);
  }
  scan.points = std::move(points);
  scan.intensities = std::move(intensities);
}

}  // namespace

Expected<SequenceSummary> writeSimulatedSequence(
    const SequenceOptions& options, const std::filesystem::path& dir,
    const std::function<void(std::size_t, std::size_t)>& progress) {
  if (options.scans <= 0 || options.scans > 100000) return makeError("scans must be in 1..100000");
  if (options.ground_truth_resolution_m < 0) return makeError("ground truth resolution < 0");
  if (options.walkers < 0 || options.walkers > 100) return makeError("walkers must be in 0..100");
  if (options.oracle_factor < 0 || options.oracle_factor > 16) {
    return makeError("oracle factor must be in 0..16");
  }
  for (const double r : options.oracle_resolutions) {
    if (!(r >= 0.01 && r <= 10.0)) return makeError("oracle resolutions must be in [0.01, 10] m");
  }
  auto lidar = lidarFor(options);
  if (!lidar) return std::unexpected(lidar.error());
  auto scene = makeScene(options.scene, static_cast<unsigned>(options.seed));
  if (!scene) return std::unexpected(scene.error());
  auto writer = DatasetWriter::create(dir);
  if (!writer) return std::unexpected(writer.error());

  SequenceSummary summary;
  const auto poses = scene->stations ? posesAtStations(scene->waypoints, options.scans)
                                     : trajectoryAlong(scene->waypoints, options.scans);
  std::vector<OracleLabeller> oracles;
  const LidarModel dense = denseLidar(*lidar, options.oracle_factor);
  if (options.oracle_factor > 0) {
    for (const double r : options.oracle_resolutions) oracles.emplace_back(r);
  }
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const WalkerScene with_walkers(*scene->scene,
                                   walkersAt(poses, options.walkers, 0.1 * static_cast<double>(i)));
    const Scene& seen_now = options.walkers > 0 ? static_cast<const Scene&>(with_walkers)
                                                : *scene->scene;
    Scan scan = simulateScan(seen_now, *lidar, poses[i], i, options.seed);
    subsample(scan, options.points_per_scan, options.seed);
    if (!oracles.empty()) {
      const Scan seen = simulateScan(*scene->scene, dense, poses[i], i, options.seed);
      const PointCloud world = seen.pointsWorld();
      for (OracleLabeller& oracle : oracles) oracle.add(world, seen.originWorld());
    }
    if (auto ok = writer->write(scan); !ok) return std::unexpected(ok.error());
    summary.points += scan.points.size();
    ++summary.scans;
    if (progress) progress(i + 1, poses.size());
  }
  if (auto ok = writer->finish(); !ok) return std::unexpected(ok.error());

  if (options.ground_truth_resolution_m > 0) {
    std::unique_ptr<octomap::OcTree> truth;
    if (const auto* octree = dynamic_cast<const OctreeScene*>(scene->scene.get())) {
      truth = std::make_unique<octomap::OcTree>(octree->tree());  // the scene is its own truth
    } else {
      truth = groundTruthOcTree(*scene->scene, options.ground_truth_resolution_m,
                                scene->scene->bounds());
    }
    std::ostringstream out;
    if (!writeOctomapBinary(*truth, out)) return makeError("cannot serialise ground truth");
    summary.ground_truth = dir / "ground_truth.bt";
    if (auto ok = writeFileAtomically(summary.ground_truth, out.str()); !ok) {
      return std::unexpected(ok.error());
    }
  }
  for (const OracleLabeller& oracle : oracles) {
    const auto path = oracleLabelsPath(dir, oracle.grid().resolution());
    if (auto ok = oracle.write(path); !ok) return std::unexpected(ok.error());
    summary.oracle_labels.push_back(path);
  }
  if (auto ok = writeFileAtomically(dir / "sim.txt", describe(options, *lidar)); !ok) {
    return std::unexpected(ok.error());
  }
  return summary;
}

}  // namespace densemap
