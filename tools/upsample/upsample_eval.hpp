#pragma once

#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <cstddef>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "densemap/eval/point_set_metrics.hpp"
#include "densemap/geometry/error.hpp"
#include "densemap/sim/lidar_simulator.hpp"
#include "densemap/upsample/iln.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace densemap::tools {

using upsample::RangeLayout;

/// densemap-upsample-eval's command line.
struct UpsampleEvalOptions {
  std::string scenes_list = "outdoor,indoor", seeds_list = "101,102",
              methods_list = "bilinear,nearest", input_text = "16x1024",
              targets_list = "64x1024,128x2048,256x4096", json_path, model_path = "models/iln.pb",
              export_dir;
  double top = 15.0, bottom = -15.0, max_range = 80.0, voxel = 0.1;
  int scans = 4, threads = 0;
  // Real data (--real).
  std::string real_path, real_layout_text = "64x2048", real_beams_path, estimate_beams_path,
                         real_splits_text, reduce_text = "4", export_real_dir;
  double real_top = 45.5, real_bottom = -44.75;
  std::size_t real_first = 0, real_limit = 0;
};
void addUpsampleEvalOptions(CLI::App& app, UpsampleEvalOptions& o);

/// The methods under test (with the ILN model when one is iln).
struct Methods {
  std::vector<upsample::Interpolation> list;
  std::shared_ptr<const upsample::IlnModel> model;
};

/// A sensor with `layout`'s beams and columns, noise-free.
[[nodiscard]] LidarModel sensorFor(const RangeLayout& layout, double max_range);

/// One method's upsampling of one scan: its errors and the upsampling time alone.
struct Score {
  upsample::RangeError range;
  eval::PointSetMetrics points;
  double ms = 0.0;
};

/// `input` upsampled by `method` to `truth`'s grid, timed and compared with `truth` (whose
/// points are `truth_points`) by range and by voxels of `voxel` metres.
[[nodiscard]] Score scoreUpsampling(const upsample::RangeImage& input,
                                    const upsample::RangeImage& truth,
                                    const PointCloud& truth_points, upsample::Interpolation method,
                                    const upsample::IlnModel* model, double voxel);

/// Scores summed over scans (means at the report).
struct Sum {
  double mae = 0, coverage = 0, iou = 0, precision = 0, recall = 0, f1 = 0, ms = 0;
  int scans = 0;
  std::vector<double> ms_each;

  [[nodiscard]] double msP50() const;
  void add(const Score& s);
};

/// The simulated scenes' sums, by (method, target).
using SimSums = std::map<std::pair<std::size_t, std::size_t>, Sum>;
/// Scans every scene and seed from its poses with the input and each target sensor, scores
/// every method (and writes the images for --export).
[[nodiscard]] Expected<SimSums> scoreSimulated(const UpsampleEvalOptions& o, const Methods& methods,
                                               const RangeLayout& input,
                                               const std::vector<RangeLayout>& targets,
                                               tbb::task_arena& arena);

/// A named range of real scans (dataset indices FIRST..LAST), reported on its own.
struct Split {
  std::string name;
  std::size_t first = 0, last = 0;
};
/// "NAME:FIRST-LAST", FIRST <= LAST.
[[nodiscard]] std::optional<Split> parseSplit(const std::string& text);

/// The real scans' sums, by (split, reduction, method).
struct RealResults {
  std::vector<Split> splits;
  std::vector<int> reduces;
  RangeLayout layout;
  std::map<std::tuple<std::size_t, std::size_t, std::size_t>, Sum> sums;
};
/// --real: every n-th beam of each real scan kept, upsampled back and compared with all.
[[nodiscard]] Expected<RealResults> scoreReal(const UpsampleEvalOptions& o, const Methods& methods,
                                              tbb::task_arena& arena);

}  // namespace densemap::tools
