// densemap-eval: accuracy of dense maps (AKIMap, BGKOctoMap, BGKOctoMap-L) and of the log-odds
// map on a dataset, by one of two protocols:
// - holdout: each scan's points are split 80/20 (by a seeded hash); maps integrate the 80%; the
//   20% are occupied test points, and one point drawn uniformly on each of their rays (short of
//   the end voxel) is a free test point.
// - oracle (simulated data): maps integrate every point; the test cells are the dense-oracle
//   labels densemap-sim wrote for the same poses (DIR/oracle_<resolution>.bt).
#include <tbb/task_arena.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "densemap/cli/guarded_main.hpp"
#include "densemap/cli/lists.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/eval/metrics.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/png_writer.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/map_factory.hpp"
#include "densemap/parallel/tbb_runner.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/sim/oracle_labels.hpp"
#include "densemap/upsample/interpolation.hpp"
#include "plots.hpp"

namespace {

using densemap::eval::Metrics;
using densemap::eval::Prediction;

struct Scan {
  densemap::PointCloud train;
  densemap::Point3f origin;
};

struct TestPoint {
  densemap::Point3f x;
  bool occupied;
};

struct RunResult {
  Metrics metrics;
  double build_s = 0.0;
  double ms_per_scan = 0.0;
};

/// The hold-out split and the free test points, reproducible from the seed.
void split(const densemap::PointCloud& points, const densemap::Point3f& origin, std::uint64_t seed,
           std::uint64_t scan, double resolution, Scan& out, std::vector<TestPoint>& tests) {
  out.origin = origin;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint64_t key = seed * 0x9E3779B97F4A7C15ULL ^ scan * 0xC2B2AE3D27D4EB4FULL ^ i;
    if (densemap::kernel::uniformFromCounter(key) >= 0.2) {
      out.train.push_back(points[i]);
      continue;
    }
    tests.push_back({points[i], true});
    const densemap::Point3f ray = points[i] - origin;
    const double length = ray.norm();
    if (length <= 2.0 * resolution) continue;
    const double t = densemap::kernel::uniformFromCounter(key ^ 0x5555555555555555ULL) *
                     (length - 2.0 * resolution) / length;
    tests.push_back({origin + static_cast<float>(t) * ray, false});
  }
}

/// The xy box of the data, for slice pictures.
struct SliceFrame {
  double x0 = 0, y0 = 0;
  int cols = 0, rows = 0;
};

/// A z-slice of a map as an RGB picture like the paper's grayscale insets: white free, black
/// occupied, gray 0.5 (and unknown); `scale` pixels per cell; north (+y) up.
struct Picture {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
};
Picture slicePicture(const SliceFrame& f, double resolution, double z, int scale,
                     const std::function<double(const densemap::Point3f&)>& p) {
  Picture image{f.cols * scale, f.rows * scale, {}};
  image.rgb.resize(static_cast<std::size_t>(image.width) * image.height * 3);
  for (int r = 0; r < f.rows; ++r) {
    for (int c = 0; c < f.cols; ++c) {
      const densemap::Point3f x(static_cast<float>(f.x0 + (c + 0.5) * resolution),
                                static_cast<float>(f.y0 + (f.rows - r - 0.5) * resolution),
                                static_cast<float>(z));
      const auto v = static_cast<std::uint8_t>(std::lround(255.0 * (1.0 - p(x))));
      for (int dy = 0; dy < scale; ++dy) {
        for (int dx = 0; dx < scale; ++dx) {
          const auto at =
              3 * (static_cast<std::size_t>(r * scale + dy) * image.width + c * scale + dx);
          image.rgb[at] = image.rgb[at + 1] = image.rgb[at + 2] = v;
        }
      }
    }
  }
  return image;
}

}  // namespace

static int runMain(int argc, char** argv) {
  std::string data, methods_list = "akimap,bgk,bgkl,raycast,akimap_rays", protocol = "holdout",
                    json_path, roc_prefix;
  double resolution = 0.1, max_range = -1.0, akimap_free_step = 0.5;
  std::uint64_t seed = 1;
  int runs = 1, threads = 0;
  std::size_t first = 0, limit = 0;
  CLI::App app{"densemap-eval: accuracy of dense and log-odds maps (hold-out protocol)"};
  app.add_option("--data", data, "Dataset (any format densemap reads)")->required();
  app.add_option("--method", methods_list,
                 "Comma-separated: akimap, bgk, bgkl, raycast, akimap_rays")
      ->capture_default_str();
  app.add_option("--protocol", protocol,
                 "holdout (any data) or oracle (densemap-sim data with --oracle-factor)")
      ->capture_default_str()
      ->check(CLI::IsMember({"holdout", "oracle"}));
  app.add_option("--resolution", resolution, "Voxel size, m")->capture_default_str();
  app.add_option("--max-range", max_range, "Ray cut-off, m (< 0: unlimited)")
      ->capture_default_str();
  app.add_option("--seed", seed, "Seed of the split and the random free samples")
      ->capture_default_str();
  app.add_option("--runs", runs, "Runs with seeds seed, seed+1, ...; mean and spread")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  app.add_option("--first", first, "First scan index")->capture_default_str();
  app.add_option("--limit", limit, "Scans to use (0: all)")->capture_default_str();
  app.add_option("--threads", threads, "Worker threads (0: all cores)")->capture_default_str();
  app.add_option("--akimap-free-step", akimap_free_step,
                 "AKIMap's free sampling distance, m: one free sample drawn at random in each "
                 "such interval of a ray (the paper's 0.5)")
      ->check(CLI::Range(0.01, 10.0))
      ->capture_default_str();
  std::vector<std::string> kernel_settings;
  app.add_option("--kernel-set", kernel_settings,
                 "Override a kernel map setting for every kernel method of the run, NAME=VALUE "
                 "(repeatable): free_step, length_scale, sf2, prior, free_margin, max_margin, "
                 "tip_margin, tip_length_scale, occupied_weight, hit_weight, hit_kernel_weight, "
                 "hit_length_voxels, negative_step, search_max, search_range, min_thickness "
                 "(core/kernel/include/densemap/kernel/kernel_map.hpp)");
  app.add_option("--json", json_path, "Write the results as JSON");
  app.add_option("--roc", roc_prefix,
                 "Write the ROC curves of the first run: PREFIX_<method>.csv and PREFIX.svg");
  std::string reliability_prefix;
  app.add_option("--reliability", reliability_prefix,
                 "Write the reliability diagrams of the first run (10 bins of predicted "
                 "probability: mean prediction, observed occupied share): PREFIX.csv and "
                 "PREFIX.svg");
  std::string slice_prefix;
  double slice_z = 1.0;
  app.add_option("--slice", slice_prefix,
                 "Write a z-slice picture per method (PREFIX_<method>.png; PREFIX_oracle.png "
                 "for the oracle labels): white free, black occupied, gray unknown");
  app.add_option("--slice-z", slice_z, "Height of the slice, m")->capture_default_str();
  std::string labels_path, upsample_method, upsample_input = "16x1024", upsample_output = "64x1024";
  double fov_top = 15.0, fov_bottom = -15.0;
  app.add_option("--labels", labels_path,
                 "Oracle labels file (default DATA/oracle_<resolution>.bt): score another "
                 "sensor's dataset on the same labels");
  app.add_option("--upsample", upsample_method,
                 "Densify each scan before mapping: bilinear, nearest or iln (sensor-frame data)")
      ->check(CLI::IsMember({"bilinear", "nearest", "iln"}));
  std::string upsample_model = "models/iln.pb";
  app.add_option("--upsample-model", upsample_model, "ILN weights file (--upsample iln)")
      ->capture_default_str();
  app.add_option("--upsample-input", upsample_input, "The sensor's grid ROWSxCOLS")
      ->capture_default_str();
  app.add_option("--upsample-output", upsample_output, "The grid mapped, ROWSxCOLS")
      ->capture_default_str();
  app.add_option("--fov-top", fov_top, "The sensor's top beam, deg")->capture_default_str();
  app.add_option("--fov-bottom", fov_bottom, "Its bottom beam, deg")->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  const auto fail = [](const std::string& message) {
    std::fprintf(stderr, "densemap-eval: error: %s\n", message.c_str());
    return 1;
  };
  if (!(resolution > 0.0 && resolution <= 10.0)) return fail("--resolution must be in (0, 10]");
  const std::vector<std::string> methods = densemap::tools::splitList(methods_list);
  if (methods.empty()) return fail("--method lists no method");
  for (const std::string& m : methods) {
    if (m != "raycast" && !densemap::kernel::parseKernelMethod(m)) {
      return fail("unknown method '" + m +
                  "' (expected akimap, bgk, bgkl, raycast or akimap_rays)");
    }
  }
  {
    densemap::kernel::KernelOptions check;
    if (auto set = densemap::kernel::applySettings(check, kernel_settings); !set) {
      return fail("--kernel-set: " + set.error().message);
    }
  }
  auto source = densemap::openScanSource(data);
  if (!source) return fail(source.error().message);
  const std::size_t total = (*source)->size();
  if (first >= total)
    return fail("--first is past the dataset's " + std::to_string(total) + " scans");
  const std::size_t end = limit == 0 ? total : std::min(total, first + limit);

  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  std::vector<densemap::PointCloud> clouds;
  std::vector<densemap::Point3f> origins;
  std::size_t rejected = 0;
  std::optional<densemap::upsample::UpsampleOptions> densify;
  if (!upsample_method.empty()) {
    auto in = densemap::upsample::parseRangeLayout(upsample_input, fov_top, fov_bottom);
    if (!in) return fail("--upsample-input: " + in.error().message);
    auto out = densemap::upsample::parseRangeLayout(upsample_output, fov_top, fov_bottom);
    if (!out) return fail("--upsample-output: " + out.error().message);
    auto options =
        densemap::upsample::makeUpsampleOptions(upsample_method, *in, *out, upsample_model);
    if (!options) return fail("--upsample: " + options.error().message);
    densify = std::move(*options);
  }
  for (std::size_t i = first; i < end; ++i) {
    auto scan = (*source)->load(i);
    if (!scan) return fail(scan.error().message);
    if (densify) {
      if (scan->frame != densemap::PointFrame::kSensor) {
        return fail("--upsample needs sensor-frame scans; " + data + " stores world-frame points");
      }
      scan->points = densemap::upsample::upsamplePoints(scan->points, *densify);
    }
    clouds.push_back(scan->pointsWorld());
    rejected += densemap::removeNonFinite(clouds.back());
    origins.push_back(scan->originWorld());
  }
  if (rejected > 0)
    std::fprintf(stderr, "densemap-eval: dropped %zu non-finite points\n", rejected);
  SliceFrame frame;
  {
    Eigen::AlignedBox3f box;
    for (std::size_t i = 0; i < clouds.size(); ++i) {
      box.extend(origins[i]);
      for (const densemap::Point3f& p : clouds[i]) box.extend(p);
    }
    if (!box.isEmpty()) {
      frame.x0 = std::floor(box.min().x() / resolution) * resolution;
      frame.y0 = std::floor(box.min().y() / resolution) * resolution;
      frame.cols = std::min(4000, static_cast<int>((box.max().x() - frame.x0) / resolution) + 1);
      frame.rows = std::min(4000, static_cast<int>((box.max().y() - frame.y0) / resolution) + 1);
    }
  }
  const int slice_scale = std::clamp(800 / std::max({frame.cols, frame.rows, 1}), 1, 8);
  const auto write_slice = [&](const std::string& name,
                               const std::function<double(const densemap::Point3f&)>& p) {
    const std::string path = slice_prefix + "_" + name + ".png";
    const Picture picture = slicePicture(frame, resolution, slice_z, slice_scale, p);
    if (auto ok = densemap::writePng(path, picture.width, picture.height, picture.rgb); !ok) {
      std::fprintf(stderr, "densemap-eval: error: %s\n", ok.error().message.c_str());
      return false;
    }
    std::fprintf(stderr, "densemap-eval: wrote %s\n", path.c_str());
    return true;
  };
  std::vector<TestPoint> oracle_tests;
  if (protocol == "oracle") {
    const auto labels = densemap::readOracleLabels(
        labels_path.empty() ? densemap::oracleLabelsPath(data, resolution)
                            : std::filesystem::path(labels_path),
        resolution);
    if (!labels) return fail(labels.error().message);
    const densemap::VoxelGrid grid(resolution);
    for (const densemap::LabelledVoxel& v : *labels) {
      oracle_tests.push_back({densemap::Point3f(static_cast<float>(grid.keyToCoord(v.key.x)),
                                                static_cast<float>(grid.keyToCoord(v.key.y)),
                                                static_cast<float>(grid.keyToCoord(v.key.z))),
                              v.occupied});
    }
    if (oracle_tests.empty()) return fail("the oracle labels hold no voxel");
    if (!slice_prefix.empty()) {
      std::unordered_map<std::uint64_t, bool> truth;
      for (const densemap::LabelledVoxel& v : *labels) truth[v.key.packed()] = v.occupied;
      if (!write_slice("oracle", [&](const densemap::Point3f& x) {
            const auto key = grid.pointToKey(x);
            const auto it = key ? truth.find(key->packed()) : truth.end();
            return it == truth.end() ? 0.5 : (it->second ? 1.0 : 0.0);
          })) {
        return 1;
      }
    }
  }

  // results[method][run]
  std::vector<std::vector<RunResult>> results(methods.size());
  std::vector<densemap::tools::RocSeries> roc_series;
  std::vector<densemap::tools::ReliabilitySeries> reliability_series;
  for (int run = 0; run < runs; ++run) {
    const std::uint64_t run_seed = seed + static_cast<std::uint64_t>(run);
    std::vector<Scan> scans(clouds.size());
    std::vector<TestPoint> tests = oracle_tests;
    for (std::size_t i = 0; i < clouds.size(); ++i) {
      if (protocol == "oracle") {
        scans[i] = {clouds[i], origins[i]};
      } else {
        split(clouds[i], origins[i], run_seed, i, resolution, scans[i], tests);
      }
    }
    for (std::size_t m = 0; m < methods.size(); ++m) {
      densemap::tools::Progress progress(
          "densemap-eval: run " + std::to_string(run + 1) + " " + methods[m] + " scan",
          scans.size());
      RunResult r;
      const auto t0 = std::chrono::steady_clock::now();
      std::function<std::optional<double>(const densemap::Point3f&)> probability;
      std::unique_ptr<densemap::kernel::KernelMap> kernel_map;
      std::unique_ptr<densemap::OccupancyMap> log_odds_map;
      if (methods[m] == "raycast") {
        log_odds_map = std::move(*densemap::makeMap(densemap::Backend::kGrid, resolution));
        log_odds_map->setRunner(densemap::tbbRunner());
        densemap::Integrator integrator({.max_range_m = max_range});
        for (std::size_t i = 0; i < scans.size(); ++i) {
          arena.execute(
              [&] { integrator.integrate(*log_odds_map, scans[i].train, scans[i].origin); });
          progress.update(i + 1);
        }
        probability = [&](const densemap::Point3f& x) -> std::optional<double> {
          const auto l = log_odds_map->logOddsAt(x);
          if (!l) return std::nullopt;
          return 1.0 / (1.0 + std::exp(-static_cast<double>(*l)));
        };
      } else {
        auto options = densemap::kernel::KernelOptions::defaults(
            *densemap::kernel::parseKernelMethod(methods[m]));
        options.max_range = max_range;
        options.seed = run_seed;
        if (options.method == densemap::kernel::KernelMethod::kAkimap) {
          options.free_step = akimap_free_step;
        }
        if (auto ok = densemap::kernel::applySettings(options, kernel_settings); !ok) {
          return fail("--kernel-set: " + ok.error().message);
        }
        kernel_map = std::make_unique<densemap::kernel::KernelMap>(resolution, options);
        for (std::size_t i = 0; i < scans.size(); ++i) {
          arena.execute([&] { kernel_map->integrate(scans[i].train, scans[i].origin); });
          progress.update(i + 1, std::to_string(kernel_map->knownCells()) + " known cells");
        }
        probability = [&](const densemap::Point3f& x) {
          const auto key = kernel_map->grid().pointToKey(x);
          return key ? kernel_map->probability(*key) : std::nullopt;
        };
      }
      r.build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      r.ms_per_scan = 1000.0 * r.build_s / static_cast<double>(scans.size());
      std::vector<Prediction> predictions;
      predictions.reserve(tests.size());
      for (const TestPoint& t : tests) {
        const auto p = probability(t.x);
        predictions.push_back({p.value_or(0.5), t.occupied, p.has_value()});
      }
      r.metrics = densemap::eval::evaluate(predictions);
      if (run == 0 && !roc_prefix.empty()) {
        const std::string path = roc_prefix + "_" + methods[m] + ".csv";
        std::ofstream csv(path);
        csv << "threshold,false_positive_rate,true_positive_rate\n";
        auto curve = densemap::eval::rocCurve(predictions);
        for (const auto& p : curve) {
          csv << p.threshold << ',' << p.false_positive_rate << ',' << p.true_positive_rate << '\n';
        }
        if (!csv) return fail("cannot write " + path);
        roc_series.push_back({methods[m], r.metrics.auc, std::move(curve)});
      }
      if (run == 0 && !reliability_prefix.empty()) {
        reliability_series.push_back({methods[m], r.metrics.ece, r.metrics.reliability});
      }
      if (run == 0 && !slice_prefix.empty() &&
          !write_slice(methods[m],
                       [&](const densemap::Point3f& x) { return probability(x).value_or(0.5); })) {
        return 1;
      }
      results[m].push_back(std::move(r));
    }
  }

  if (!roc_series.empty()) {
    std::ostringstream title;
    title << "ROC, " << protocol << " protocol, " << resolution << " m";
    if (auto ok = densemap::tools::writeRocSvg(roc_prefix + ".svg", title.str(), roc_series); !ok) {
      return fail(ok.error().message);
    }
    std::fprintf(stderr, "densemap-eval: wrote %s.svg\n", roc_prefix.c_str());
  }
  if (!reliability_series.empty()) {
    std::ostringstream title, csv;
    title << "Reliability, " << protocol << " protocol, " << resolution << " m";
    csv << "method,bin_lower,bin_upper,count,mean_predicted,observed\n";
    for (const auto& s : reliability_series) {
      for (const auto& b : s.bins) {
        csv << s.name << ',' << b.lower << ',' << b.upper << ',' << b.count << ','
            << b.mean_predicted << ',' << b.observed << '\n';
      }
    }
    if (auto ok = densemap::writeFileAtomically(reliability_prefix + ".csv", csv.str()); !ok) {
      return fail(ok.error().message);
    }
    if (auto ok = densemap::tools::writeReliabilitySvg(reliability_prefix + ".svg", title.str(),
                                                       reliability_series);
        !ok) {
      return fail(ok.error().message);
    }
    std::fprintf(stderr, "densemap-eval: wrote %s.csv and %s.svg\n", reliability_prefix.c_str(),
                 reliability_prefix.c_str());
  }
  const auto stat = [&](const std::vector<RunResult>& rs, auto field) {
    double mean = 0.0, sq = 0.0;
    for (const RunResult& r : rs) mean += field(r);
    mean /= static_cast<double>(rs.size());
    for (const RunResult& r : rs) sq += (field(r) - mean) * (field(r) - mean);
    return std::pair<double, double>(mean, std::sqrt(sq / static_cast<double>(rs.size())));
  };
  std::printf("densemap-eval: %s, protocol %s, resolution %g m, %zu scans, %d run(s), seed %llu\n",
              data.c_str(), protocol.c_str(), resolution, clouds.size(), runs,
              static_cast<unsigned long long>(seed));
  std::printf("%-11s %14s %7s %7s %7s %8s %7s %8s %7s %8s %8s\n", "method", "auc (+-sd)", "mse",
              "ece", "acc_occ", "acc_free", "occ>0.7", "free<0.3", "known", "build_s", "ms/scan");
  std::string json = "{\"results\": [";
  for (std::size_t m = 0; m < methods.size(); ++m) {
    const auto& rs = results[m];
    const auto auc = stat(rs, [](const RunResult& r) { return r.metrics.auc; });
    const auto mse = stat(rs, [](const RunResult& r) { return r.metrics.mse; });
    const auto occ = stat(rs, [](const RunResult& r) { return r.metrics.acc_occupied; });
    const auto fre = stat(rs, [](const RunResult& r) { return r.metrics.acc_free; });
    const auto occ_band = stat(rs, [](const RunResult& r) { return r.metrics.acc_occupied_band; });
    const auto free_band = stat(rs, [](const RunResult& r) { return r.metrics.acc_free_band; });
    const auto build = stat(rs, [](const RunResult& r) { return r.build_s; });
    const auto ms = stat(rs, [](const RunResult& r) { return r.ms_per_scan; });
    const auto ece = stat(rs, [](const RunResult& r) { return r.metrics.ece; });
    const auto known = stat(rs, [](const RunResult& r) { return r.metrics.coverage; });
    std::printf("%-11s %7.4f+-%.4f %7.4f %7.4f %7.4f %8.4f %7.4f %8.4f %7.4f %8.2f %8.1f\n",
                methods[m].c_str(), auc.first, auc.second, mse.first, ece.first, occ.first,
                fre.first, occ_band.first, free_band.first, known.first, build.first, ms.first);
    char entry[768];
    std::snprintf(entry, sizeof(entry),
                  "%s{\"method\": \"%s\", \"protocol\": \"%s\", \"resolution\": %g, \"auc\": %.6f, "
                  "\"auc_sd\": %.6f, \"mse\": %.6f, \"acc_occupied\": %.6f, \"acc_free\": %.6f, "
                  "\"build_s\": %.4f, \"ms_per_scan\": %.3f, \"ece\": %.6f, \"known\": %.6f, "
                  "\"runs\": %d}",
                  m == 0 ? "" : ", ", methods[m].c_str(), protocol.c_str(), resolution, auc.first,
                  auc.second, mse.first, occ.first, fre.first, build.first, ms.first, ece.first,
                  known.first, runs);
    json += entry;
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
  return densemap::cli::guardedMain("densemap-eval", [&] { return runMain(argc, argv); });
}
