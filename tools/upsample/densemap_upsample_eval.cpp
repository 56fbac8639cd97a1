// densemap-upsample-eval: LiDAR range-image upsampling measured as in the dissertation's
// Table 4.1. densemap-sim's scenes are scanned from the same poses by a sparse input sensor
// (16 x 1024 by default) and by denser target sensors; each method upsamples the input to each
// target grid; MAE of range and voxel IoU / precision / recall / F1 of the points compare it
// with what the target sensor saw.
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/lists.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/eval/point_set_metrics.hpp"
#include "densemap/geometry/percentile.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/sim/lidar_simulator.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/trajectory.hpp"
#include "densemap/upsample/iln.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace {

using densemap::upsample::RangeLayout;

/// A sensor with `layout`'s beams and columns, noise-free.
densemap::LidarModel sensorFor(const RangeLayout& layout, double max_range) {
  densemap::LidarModel m;
  m.name = std::to_string(layout.rows) + "x" + std::to_string(layout.cols);
  for (int r = 0; r < layout.rows; ++r) m.elevations_deg.push_back(layout.elevationDeg(r));
  m.columns = layout.cols;
  m.min_range_m = 0.5;
  m.max_range_m = max_range;
  return m;
}

/// One method's upsampling of one scan: its errors and the upsampling time alone.
struct Score {
  densemap::upsample::RangeError range;
  densemap::eval::PointSetMetrics points;
  double ms = 0.0;
};

/// `input` upsampled by `method` to `truth`'s grid, timed and compared with `truth` (whose
/// points are `truth_points`) by range and by voxels of `voxel` metres.
Score scoreUpsampling(const densemap::upsample::RangeImage& input,
                      const densemap::upsample::RangeImage& truth,
                      const densemap::PointCloud& truth_points,
                      densemap::upsample::Interpolation method,
                      const densemap::upsample::IlnModel* model, double voxel) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto predicted = densemap::upsample::upsample(input, truth.layout, method, model);
  Score score;
  score.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  score.range = *densemap::upsample::compareRanges(predicted, truth);
  score.points = densemap::eval::comparePointSets(densemap::upsample::backProject(predicted),
                                                  truth_points, voxel);
  return score;
}

struct Sum {
  double mae = 0, coverage = 0, iou = 0, precision = 0, recall = 0, f1 = 0, ms = 0;
  int scans = 0;
  std::vector<double> ms_each;

  [[nodiscard]] double msP50() const { return densemap::percentile(ms_each, 0.5); }

  void add(const Score& s) {
    mae += s.range.mae;
    coverage += s.range.coverage;
    iou += s.points.iou;
    precision += s.points.precision;
    recall += s.points.recall;
    f1 += s.points.f1;
    ms += s.ms;
    ms_each.push_back(s.ms);
    ++scans;
  }
};

/// A named range of real scans (dataset indices FIRST..LAST), reported on its own.
struct Split {
  std::string name;
  std::size_t first = 0, last = 0;
};

/// "NAME:FIRST-LAST", FIRST <= LAST.
std::optional<Split> parseSplit(const std::string& text) {
  const auto colon = text.find(':');
  const auto dash = colon == std::string::npos ? colon : text.find('-', colon);
  if (colon == 0 || dash == std::string::npos) return std::nullopt;
  const auto number = [](std::string_view digits, std::size_t& value) {
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    return ec == std::errc() && end == digits.data() + digits.size() && !digits.empty();
  };
  Split split{text.substr(0, colon), 0, 0};
  const std::string_view view(text);
  if (!number(view.substr(colon + 1, dash - colon - 1), split.first) ||
      !number(view.substr(dash + 1), split.last) || split.first > split.last) {
    return std::nullopt;
  }
  return split;
}

}  // namespace

static int runMain(int argc, char** argv) {
  std::string scenes_list = "outdoor,indoor", seeds_list = "101,102",
              methods_list = "bilinear,nearest", input_text = "16x1024",
              targets_list = "64x1024,128x2048,256x4096", json_path;
  double top = 15.0, bottom = -15.0, max_range = 80.0, voxel = 0.1;
  int scans = 4, threads = 0;
  CLI::App app{"densemap-upsample-eval: LiDAR upsampling accuracy on simulated scenes"};
  app.add_option("--scenes", scenes_list, "densemap-sim scenes (test split)")
      ->capture_default_str();
  app.add_option("--seeds", seeds_list, "Scene seeds (test split), e.g. 101,102 or 1..40")
      ->capture_default_str();
  app.add_option("--scans", scans, "Poses per scene and seed")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  app.add_option("--input", input_text, "Input grid ROWSxCOLS")->capture_default_str();
  app.add_option("--targets", targets_list, "Target grids, comma-separated")->capture_default_str();
  app.add_option("--fov-top", top, "Top beam elevation, deg")->capture_default_str();
  app.add_option("--fov-bottom", bottom, "Bottom beam elevation, deg")->capture_default_str();
  app.add_option("--max-range", max_range, "Sensor range, m")->capture_default_str();
  std::string model_path = "models/iln.pb";
  app.add_option("--methods", methods_list, "bilinear, nearest, iln")->capture_default_str();
  app.add_option("--model", model_path, "ILN weights file (for --methods iln)")
      ->capture_default_str();
  app.add_option("--voxel", voxel, "Voxel size of the point metrics, m")->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  app.add_option("--json", json_path, "Write the results as JSON");
  std::string real_path, real_layout_text = "64x2048", real_beams_path, estimate_beams_path,
                         real_splits_text, reduce_text = "4", export_real_dir;
  double real_top = 45.5, real_bottom = -44.75;
  std::size_t real_first = 0, real_limit = 0;
  app.add_option("--real", real_path,
                 "Also test on real scans (sensor frame, e.g. ../shared/data/balm-realworld): "
                 "keep every --reduce-th beam, upsample back, compare with all beams");
  app.add_option("--real-grid", real_layout_text,
                 "The real sensor's grid ROWSxCOLS (ROWS must match --real-beams)")
      ->capture_default_str();
  app.add_option("--real-top", real_top, "Its top beam, deg (BALM's OS0-64: 45.5)")
      ->capture_default_str();
  app.add_option("--real-bottom", real_bottom, "Its bottom beam, deg (BALM's: -44.75)")
      ->capture_default_str();
  app.add_option("--real-beams", real_beams_path,
                 "The real sensor's beam table (one elevation per line, deg, top first; e.g. "
                 "config/sensors/balm-os0-64.beams) instead of evenly spread beams");
  app.add_option(
      "--estimate-beams", estimate_beams_path,
      "Estimate the real sensor's beam table from the --real scans (20 or more; k-means on the "
      "elevations of returns beyond 3 m), write it to this file and use it");
  app.add_option("--reduce", reduce_text,
                 "Keep every n-th real beam; a comma-separated list tests each (e.g. 4,2)")
      ->capture_default_str();
  app.add_option("--real-first", real_first, "First real scan")->capture_default_str();
  app.add_option("--real-limit", real_limit, "Real scans to use (0: all)")->capture_default_str();
  app.add_option("--real-splits", real_splits_text,
                 "Report the real scans per split, NAME:FIRST-LAST of dataset indices, "
                 "comma-separated (e.g. train:0-39,test:40-79); default one split 'all'");
  app.add_option("--export-real", export_real_dir,
                 "Write every real scan's full range image (and the beam table) as training data "
                 "for tools/iln: DIR/index.csv, raw float32 row-major files");
  std::string export_dir;
  app.add_option("--export", export_dir,
                 "Also write every simulated range image (input and targets) as raw float32 "
                 "row-major files plus DIR/index.csv: training data for tools/iln");
  CLI11_PARSE(app, argc, argv);

  const auto fail = [](const std::string& message) {
    std::fprintf(stderr, "densemap-upsample-eval: error: %s\n", message.c_str());
    return 1;
  };
  std::vector<densemap::upsample::Interpolation> methods;
  std::shared_ptr<const densemap::upsample::IlnModel> model;
  for (const std::string& m : densemap::tools::splitList(methods_list)) {
    auto parsed = densemap::upsample::parseInterpolation(m);
    if (!parsed) return fail(parsed.error().message);
    if (*parsed == densemap::upsample::Interpolation::kIln && !model) {
      auto loaded = densemap::upsample::IlnModel::load(model_path);
      if (!loaded) return fail(loaded.error().message + " (--model)");
      model = std::make_shared<const densemap::upsample::IlnModel>(std::move(*loaded));
      std::fprintf(stderr,
                   "densemap-upsample-eval: ILN model %s: width %d, %d blocks, dim %d, "
                   "%zu parameters\n",
                   model_path.c_str(), model->width(), model->blocks(), model->dim(),
                   model->parameters());
    }
    methods.push_back(*parsed);
  }
  if (methods.empty()) return fail("--methods lists no method");
  if (!(voxel > 0.0 && voxel <= 10.0)) return fail("--voxel must be in (0, 10]");
  if (!(max_range > 1.0 && max_range <= 1000.0)) return fail("--max-range must be in (1, 1000]");
  auto input = densemap::upsample::parseRangeLayout(input_text, top, bottom);
  if (!input) return fail(input.error().message);
  std::vector<RangeLayout> targets;
  for (const std::string& t : densemap::tools::splitList(targets_list)) {
    auto layout = densemap::upsample::parseRangeLayout(t, top, bottom);
    if (!layout) return fail(layout.error().message);
    targets.push_back(*layout);
  }
  const auto parsed_seeds = densemap::tools::parseNumberList(seeds_list);
  if (!parsed_seeds) return fail("--seeds: " + parsed_seeds.error());
  const std::vector<unsigned>& seeds = *parsed_seeds;
  const std::vector<std::string> scene_names = densemap::tools::splitList(scenes_list);
  if (scene_names.empty() || seeds.empty()) return fail("no scene or no seed to test on");

  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  std::string index = "scene,seed,pose,rows,cols,top_deg,bottom_deg,file\n";
  const auto export_image = [&](const std::string& scene, unsigned seed, std::size_t pose,
                                const densemap::upsample::RangeImage& image) {
    if (export_dir.empty()) return densemap::Expected<void>{};
    const RangeLayout& l = image.layout;
    const std::string file = scene + "_" + std::to_string(seed) + "_" + std::to_string(pose) + "_" +
                             std::to_string(l.rows) + "x" + std::to_string(l.cols) + ".f32";
    std::ostringstream row;
    row << scene << ',' << seed << ',' << pose << ',' << l.rows << ',' << l.cols << ',' << l.top_deg
        << ',' << l.bottom_deg << ',' << file << '\n';
    index += row.str();
    return densemap::writeFileAtomically(
        std::filesystem::path(export_dir) / file,
        std::string(reinterpret_cast<const char*>(image.range.data()),
                    image.range.size() * sizeof(float)));
  };
  if (!export_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(export_dir, ec);
    if (ec) return fail("cannot create " + export_dir + ": " + ec.message());
  }
  std::string export_error;
  std::map<std::pair<std::size_t, std::size_t>, Sum> sums;  // (method, target)
  const densemap::LidarModel input_sensor = sensorFor(*input, max_range);
  densemap::tools::Progress progress("densemap-upsample-eval: scan",
                                     scene_names.size() * seeds.size() * scans);
  std::size_t done = 0;
  for (const std::string& name : scene_names) {
    for (const unsigned seed : seeds) {
      auto scene = densemap::makeScene(name, seed);
      if (!scene) return fail(scene.error().message);
      const auto poses = densemap::trajectoryAlong(scene->waypoints, scans);
      for (std::size_t i = 0; i < poses.size(); ++i) {
        arena.execute([&] {
          const auto sparse =
              densemap::simulateScan(*scene->scene, input_sensor, poses[i], i, seed);
          const auto low = densemap::upsample::project(sparse.points, *input);
          if (auto ok = export_image(name, seed, i, low); !ok) export_error = ok.error().message;
          for (std::size_t t = 0; t < targets.size(); ++t) {
            const auto dense = densemap::simulateScan(
                *scene->scene, sensorFor(targets[t], max_range), poses[i], i, seed);
            const auto truth = densemap::upsample::project(dense.points, targets[t]);
            if (auto ok = export_image(name, seed, i, truth); !ok) {
              export_error = ok.error().message;
            }
            const auto truth_points = densemap::upsample::backProject(truth);
            for (std::size_t m = 0; m < methods.size(); ++m) {
              sums[{m, t}].add(
                  scoreUpsampling(low, truth, truth_points, methods[m], model.get(), voxel));
            }
          }
        });
        progress.update(++done);
      }
    }
  }

  if (!export_error.empty()) return fail(export_error);
  if (!export_dir.empty()) {
    if (auto ok =
            densemap::writeFileAtomically(std::filesystem::path(export_dir) / "index.csv", index);
        !ok) {
      return fail(ok.error().message);
    }
    std::fprintf(stderr, "densemap-upsample-eval: wrote the range images and %s/index.csv\n",
                 export_dir.c_str());
  }

  // Real data: (split, reduce, method) -> sums over scans.
  std::vector<Split> splits;
  std::vector<int> reduces;
  std::map<std::tuple<std::size_t, std::size_t, std::size_t>, Sum> real_sums;
  RangeLayout real_layout;
  if (!real_path.empty()) {
    for (const std::string& item : densemap::tools::splitList(reduce_text)) {
      const auto n = densemap::tools::parseNumberList(item);
      if (!n || n->size() != 1 || n->front() < 2 || n->front() > 16) {
        return fail("--reduce: '" + item + "' is not a number in 2..16");
      }
      reduces.push_back(static_cast<int>(n->front()));
    }
    if (reduces.empty()) return fail("--reduce lists nothing");
    auto layout = densemap::upsample::parseRangeLayout(real_layout_text, real_top, real_bottom);
    if (!layout) return fail("--real-grid: " + layout.error().message);
    real_layout = *layout;
    auto source = densemap::openScanSource(real_path);
    if (!source) return fail(source.error().message);
    const std::size_t total = (*source)->size();
    if (real_first >= total) return fail("--real-first is past the data's scans");
    const std::size_t end = real_limit == 0 ? total : std::min(total, real_first + real_limit);
    if (real_splits_text.empty()) {
      splits.push_back({"all", real_first, end - 1});
    } else {
      for (const std::string& item : densemap::tools::splitList(real_splits_text)) {
        const auto split = parseSplit(item);
        if (!split) return fail("--real-splits: '" + item + "' is not NAME:FIRST-LAST");
        splits.push_back(*split);
      }
    }
    const auto scan_of = [&](std::size_t i) -> densemap::Expected<densemap::PointCloud> {
      auto scan = (*source)->load(i);
      if (!scan) return std::unexpected(scan.error());
      if (scan->frame != densemap::PointFrame::kSensor) {
        return densemap::makeError(real_path +
                                   " stores world-frame points: range images need sensor-frame "
                                   "scans");
      }
      return std::move(scan->points);
    };
    if (!estimate_beams_path.empty()) {
      std::vector<densemap::PointCloud> clouds;
      for (std::size_t i = real_first; i < end; ++i) {
        auto points = scan_of(i);
        if (!points) return fail(points.error().message);
        clouds.push_back(std::move(*points));
      }
      auto beams = densemap::upsample::estimateBeams(clouds, real_layout.rows);
      if (!beams) return fail("--estimate-beams: " + beams.error().message);
      std::ostringstream comment;
      comment << "Beam table of " << real_path << " (scans " << real_first << ".." << end - 1
              << "), estimated by densemap-upsample-eval --estimate-beams:\nelevations, deg, "
                 "top beam first";
      if (auto ok = densemap::writeFileAtomically(
              estimate_beams_path, densemap::upsample::formatBeamTable(*beams, comment.str()));
          !ok) {
        return fail(ok.error().message);
      }
      std::fprintf(stderr, "densemap-upsample-eval: wrote the beam table %s\n",
                   estimate_beams_path.c_str());
      real_beams_path = estimate_beams_path;
    }
    if (!real_beams_path.empty()) {
      auto beams = densemap::upsample::readBeamTable(real_beams_path);
      if (!beams) return fail(beams.error().message);
      auto with = densemap::upsample::withBeams(std::move(*beams), real_layout.cols);
      if (!with) return fail(real_beams_path + ": " + with.error().message);
      if (with->rows != real_layout.rows) {
        return fail(real_beams_path + " has " + std::to_string(with->rows) +
                    " beams but --real-grid has " + std::to_string(real_layout.rows) + " rows");
      }
      real_layout = std::move(*with);
    }
    std::string real_index = "scene,seed,pose,rows,cols,top_deg,bottom_deg,file,beams\n";
    const std::string beams_file = "beams_" + std::to_string(real_layout.rows) + ".txt";
    if (!export_real_dir.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(export_real_dir, ec);
      if (ec) return fail("cannot create " + export_real_dir + ": " + ec.message());
      std::vector<double> beams = real_layout.beams_deg;
      for (int r = 0; beams.empty() && r < real_layout.rows; ++r) {
        beams.push_back(real_layout.elevationDeg(r));
      }
      if (auto ok = densemap::writeFileAtomically(
              std::filesystem::path(export_real_dir) / beams_file,
              densemap::upsample::formatBeamTable(beams, "beams of " + real_path));
          !ok) {
        return fail(ok.error().message);
      }
    }
    densemap::tools::Progress real_progress("densemap-upsample-eval: real scan", end - real_first);
    std::size_t outside = 0, collisions = 0, points = 0;
    for (std::size_t i = real_first; i < end; ++i) {
      auto scan = scan_of(i);
      if (!scan) return fail(scan.error().message);
      densemap::upsample::ProjectionStats stats;
      const auto truth = densemap::upsample::project(*scan, real_layout, &stats);
      outside += stats.outside_fov;
      collisions += stats.collisions;
      points += stats.points;
      if (!export_real_dir.empty()) {
        const std::string file = "real_" + std::to_string(i) + ".f32";
        std::ostringstream row;
        row << std::setprecision(10) << "real," << i << ",0," << real_layout.rows << ','
            << real_layout.cols << ',' << real_layout.top_deg << ',' << real_layout.bottom_deg
            << ',' << file << ',' << beams_file << '\n';
        real_index += row.str();
        if (auto ok = densemap::writeFileAtomically(
                std::filesystem::path(export_real_dir) / file,
                std::string(reinterpret_cast<const char*>(truth.range.data()),
                            truth.range.size() * sizeof(float)));
            !ok) {
          return fail(ok.error().message);
        }
      }
      // Each (reduction, method) is scored once and counted in every split holding the scan.
      std::vector<std::size_t> in_splits;
      for (std::size_t sp = 0; sp < splits.size(); ++sp) {
        if (i >= splits[sp].first && i <= splits[sp].last) in_splits.push_back(sp);
      }
      if (!in_splits.empty()) {
        const auto truth_points = densemap::upsample::backProject(truth);
        for (std::size_t r = 0; r < reduces.size(); ++r) {
          const auto sparse = densemap::upsample::keepEveryNthRow(truth, reduces[r]);
          arena.execute([&] {
            for (std::size_t m = 0; m < methods.size(); ++m) {
              const Score score =
                  scoreUpsampling(sparse, truth, truth_points, methods[m], model.get(), voxel);
              for (const std::size_t sp : in_splits) real_sums[{sp, r, m}].add(score);
            }
          });
        }
      }
      real_progress.update(i + 1 - real_first);
    }
    std::fprintf(stderr,
                 "densemap-upsample-eval: real scans projected: %zu points, %zu outside the "
                 "field of view, %zu sharing a pixel with a nearer one\n",
                 points, outside, collisions);
    if (!export_real_dir.empty()) {
      if (auto ok = densemap::writeFileAtomically(
              std::filesystem::path(export_real_dir) / "index.csv", real_index);
          !ok) {
        return fail(ok.error().message);
      }
      std::fprintf(stderr, "densemap-upsample-eval: wrote the real range images and %s/index.csv\n",
                   export_real_dir.c_str());
    }
  }

  std::printf(
      "densemap-upsample-eval: scenes %s, seeds %s, %d scans each, input %dx%d, FOV "
      "[%g, %g] deg, max range %g m, voxel %g m\n",
      scenes_list.c_str(), seeds_list.c_str(), scans, input->rows, input->cols, bottom, top,
      max_range, voxel);
  std::printf("%-9s %-10s %8s %8s %7s %9s %7s %7s %9s %7s\n", "method", "target", "mae_m",
              "coverage", "iou", "precision", "recall", "f1", "ms/scan", "ms_p50");
  std::string json = "{\"results\": [";
  bool first = true;
  const auto report = [&](const std::string& method, const std::string& dataset,
                          const RangeLayout& grid, Sum& sum, const char* suffix) {
    const double n = sum.scans;
    const std::string size = std::to_string(grid.rows) + "x" + std::to_string(grid.cols);
    const double p50 = sum.msP50();
    std::printf("%-9s %-10s %8.3f %8.3f %7.3f %9.3f %7.3f %7.3f %9.1f %7.1f%s\n", method.c_str(),
                size.c_str(), sum.mae / n, sum.coverage / n, sum.iou / n, sum.precision / n,
                sum.recall / n, sum.f1 / n, sum.ms / n, p50, suffix);
    char entry[512];
    std::snprintf(entry, sizeof(entry),
                  "%s{\"method\": \"%s\", \"dataset\": \"%s\", \"rows\": %d, \"cols\": %d, "
                  "\"mae\": %.5f, \"iou\": %.5f, \"precision\": %.5f, \"recall\": %.5f, "
                  "\"f1\": %.5f, \"ms_per_scan\": %.3f, \"ms_p50\": %.3f}",
                  first ? "" : ", ", method.c_str(), dataset.c_str(), grid.rows, grid.cols,
                  sum.mae / n, sum.iou / n, sum.precision / n, sum.recall / n, sum.f1 / n,
                  sum.ms / n, p50);
    json += entry;
    first = false;
  };
  for (std::size_t t = 0; t < targets.size(); ++t) {
    for (std::size_t m = 0; m < methods.size(); ++m) {
      report(std::string(densemap::upsample::interpolationName(methods[m])), "sim:" + scenes_list,
             targets[t], sums[{m, t}], "");
    }
  }
  for (auto& [key, sum] : real_sums) {
    const auto [split, reduce, m] = key;
    const std::string suffix = "  (real " + splits[split].name + " " +
                               std::to_string(splits[split].first) + "-" +
                               std::to_string(splits[split].last) + ", every " +
                               std::to_string(reduces[reduce]) + "-th beam)";
    report(
        std::string(densemap::upsample::interpolationName(methods[m])),
        "real:" + real_path + ":" + splits[split].name + ":every" + std::to_string(reduces[reduce]),
        real_layout, sum, suffix.c_str());
  }
  json += "]}\n";
  if (!json_path.empty()) {
    if (auto ok = densemap::writeFileAtomically(json_path, json); !ok) {
      return fail(ok.error().message);
    }
  }
  return 0;
}

int main(int argc, char** argv) {
  return densemap::cli::guardedMain("densemap-upsample-eval", [&] { return runMain(argc, argv); });
}
