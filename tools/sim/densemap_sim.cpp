// densemap-sim: writes a simulated LiDAR dataset (docs/datasets.md) with ground truth.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <cstdio>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/ros2/recording.hpp"
#include "densemap/sim/sequence.hpp"

static int runMain(int argc, char** argv) {
  CLI::App app{"densemap-sim: simulated LiDAR datasets (scans/*.bin, poses.txt, ground_truth.bt)"};
  densemap::SequenceOptions o;
  std::string out;
  int threads = 0;
  app.add_option("--out", out, "Output dataset directory")->required();
  app.add_option(
         "--scene", o.scene,
         "indoor, outdoor, street:LENGTH_M (the outdoor street made LENGTH_M long, for long "
         "drives), structured, unstructured (the AKIMap benchmark's 10 x 7 x 2 m "
         "scenes, 4 stations), or an OctoMap .bt file (e.g. geb079.bt)")
      ->capture_default_str();
  app.add_option("--sensor", o.sensor, "vlp16, hdl64, os128 or os0-64")->capture_default_str();
  app.add_option("--columns", o.columns, "Azimuth steps per revolution (0: the sensor's)")
      ->capture_default_str();
  app.add_option("--beams", o.beams,
                 "Replace the sensor's beams by this many, evenly from --fov-top to --fov-bottom "
                 "(0: the sensor's own)")
      ->capture_default_str();
  app.add_option("--fov-top", o.top_deg, "Top beam with --beams, deg")->capture_default_str();
  app.add_option("--fov-bottom", o.bottom_deg, "Bottom beam with --beams, deg")
      ->capture_default_str();
  app.add_option("--max-range", o.max_range_m, "Max range in m (0: the sensor's)")
      ->capture_default_str();
  app.add_option("--noise-std", o.noise_std_m, "Gaussian range noise, m")->capture_default_str();
  app.add_option("--dropout", o.dropout, "Probability a return is lost")->capture_default_str();
  app.add_option("--scans", o.scans, "Scans along the scene's path")->capture_default_str();
  app.add_option("--seed", o.seed, "Seed for the scene layout and the noise")
      ->capture_default_str();
  app.add_option("--gt-resolution", o.ground_truth_resolution_m,
                 "Ground-truth voxel size in m (0: no ground truth)")
      ->capture_default_str();
  app.add_option("--points-per-scan", o.points_per_scan,
                 "Keep at most this many points per scan, drawn at random (0: all)")
      ->capture_default_str();
  app.add_option("--walkers", o.walkers,
                 "People walking beside the path (upright cylinders pacing 16 m at 1.4 m/s; scans "
                 "0.1 s apart): what map.decay forgets. The ground truth has the static scene only")
      ->capture_default_str()
      ->check(CLI::Range(0, 100));
  app.add_option("--oracle-factor", o.oracle_factor,
                 "Also write dense-oracle labels: a noise-free sensor with this factor times the "
                 "beams and columns, same poses (0: none)")
      ->capture_default_str()
      ->check(CLI::Range(0, 16));
  app.add_option("--oracle-resolutions", o.oracle_resolutions,
                 "Voxel sizes (m) of the oracle labels, one oracle_<res>.bt each")
      ->delimiter(',')
      ->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  std::string mcap, mcap_compression = "zstd";
  app.add_option("--mcap", mcap,
                 "Also write the scans as a ROS 2 MCAP bag: PointCloud2 on /points and TF, as "
                 "densemap replay --ros publishes them (what densemap replay, densemap-map and "
                 "densemap-bench read back); FILE.db3: rosbag2's SQLite storage instead");
  app.add_option("--mcap-compression", mcap_compression, "The bag's chunks: none, zstd or lz4")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  const auto compression = densemap::ros2::parseMcapCompression(mcap_compression);
  if (!compression) {
    std::fprintf(stderr, "densemap-sim: error: %s\n", compression.error().message.c_str());
    return 2;
  }

  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  densemap::Expected<densemap::SequenceSummary> summary;
  arena.execute([&] {
    densemap::tools::Progress progress("densemap-sim: scan", static_cast<std::size_t>(o.scans));
    summary = densemap::writeSimulatedSequence(
        o, out, [&](std::size_t done, std::size_t) { progress.update(done); });
  });
  if (!summary) {
    std::fprintf(stderr, "densemap-sim: error: %s\n", summary.error().message.c_str());
    return 1;
  }
  std::printf("wrote %zu scans (%zu points, %.0f per scan) to %s%s%s\n", summary->scans,
              summary->points, static_cast<double>(summary->points) / summary->scans, out.c_str(),
              summary->ground_truth.empty() ? "" : ", ground truth ",
              summary->ground_truth.string().c_str());
  for (const auto& path : summary->oracle_labels) {
    std::printf("oracle labels %s\n", path.string().c_str());
  }
  if (!mcap.empty()) {
    auto source = densemap::openScanSource(out);
    densemap::Expected<void> written =
        source ? densemap::Expected<void>{} : std::unexpected(source.error());
    if (source) {
      densemap::tools::Progress progress("densemap-sim: bag scan", (*source)->size());
      written = densemap::ros2::writeRecording(**source, 0, (*source)->size(), mcap, *compression,
                                               [&](std::size_t n) { progress.update(n); });
    }
    if (!written) {
      std::fprintf(stderr, "densemap-sim: error: %s\n", written.error().message.c_str());
      return 1;
    }
    std::printf("ROS 2 bag %s (%s chunks)\n", mcap.c_str(), mcap_compression.c_str());
  }
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-sim", [&] { return runMain(argc, argv); });
}
