#include "densemap/sim/sequence.hpp"

#include <sstream>

#include "densemap/io/dataset_writer.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/sim/ground_truth.hpp"
#include "densemap/sim/lidar_simulator.hpp"
#include "densemap/sim/octree_scene.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/trajectory.hpp"

namespace densemap {
namespace {

Expected<LidarModel> lidarFor(const SequenceOptions& o) {
  auto lidar = lidarPreset(o.sensor);
  if (!lidar) return lidar;
  if (o.columns != 0) lidar->columns = o.columns;
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
    << "\nground_truth_resolution_m " << o.ground_truth_resolution_m << "\n";
  return s.str();
}

}  // namespace

Expected<SequenceSummary> writeSimulatedSequence(
    const SequenceOptions& options, const std::filesystem::path& dir,
    const std::function<void(std::size_t, std::size_t)>& progress) {
  if (options.scans <= 0 || options.scans > 100000) return makeError("scans must be in 1..100000");
  if (options.ground_truth_resolution_m < 0) return makeError("ground truth resolution < 0");
  auto lidar = lidarFor(options);
  if (!lidar) return std::unexpected(lidar.error());
  auto scene = makeScene(options.scene, static_cast<unsigned>(options.seed));
  if (!scene) return std::unexpected(scene.error());
  auto writer = DatasetWriter::create(dir);
  if (!writer) return std::unexpected(writer.error());

  SequenceSummary summary;
  const auto poses = trajectoryAlong(scene->waypoints, options.scans);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Scan scan = simulateScan(*scene->scene, *lidar, poses[i], i, options.seed);
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
    if (!truth->writeBinaryConst(out)) return makeError("cannot serialise ground truth");
    summary.ground_truth = dir / "ground_truth.bt";
    if (auto ok = writeFileAtomically(summary.ground_truth, out.str()); !ok) {
      return std::unexpected(ok.error());
    }
  }
  if (auto ok = writeFileAtomically(dir / "sim.txt", describe(options, *lidar)); !ok) {
    return std::unexpected(ok.error());
  }
  return summary;
}

}  // namespace densemap
