#include <filesystem>
#include <sstream>

#include "densemap/cli/lists.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/trajectory.hpp"
#include "upsample_eval.hpp"

namespace densemap::tools {
namespace {

/// --export: every simulated range image as a raw float32 file, listed in DIR/index.csv.
class ImageExport {
 public:
  explicit ImageExport(std::string dir) : dir_(std::move(dir)) {}
  [[nodiscard]] Expected<void> start() const {
    if (dir_.empty()) return {};
    std::error_code ec;
    std::filesystem::create_directories(dir_, ec);
    if (ec) return makeError("cannot create " + dir_ + ": " + ec.message());
    return {};
  }
  /// Called from the arena's tasks one scan at a time (the scans are sequential).
  void add(const std::string& scene, unsigned seed, std::size_t pose,
           const upsample::RangeImage& image) {
    if (dir_.empty()) return;
    const RangeLayout& l = image.layout;
    const std::string file = scene + "_" + std::to_string(seed) + "_" + std::to_string(pose) + "_" +
                             std::to_string(l.rows) + "x" + std::to_string(l.cols) + ".f32";
    std::ostringstream row;
    row << scene << ',' << seed << ',' << pose << ',' << l.rows << ',' << l.cols << ',' << l.top_deg
        << ',' << l.bottom_deg << ',' << file << '\n';
    index_ += row.str();
    auto ok = writeFileAtomically(std::filesystem::path(dir_) / file,
                                  std::string(reinterpret_cast<const char*>(image.range.data()),
                                              image.range.size() * sizeof(float)));
    if (!ok) error_ = ok.error().message;
  }
  [[nodiscard]] Expected<void> finish() const {
    if (!error_.empty()) return makeError(error_);
    if (dir_.empty()) return {};
    if (auto ok = writeFileAtomically(std::filesystem::path(dir_) / "index.csv", index_); !ok) {
      return ok;
    }
    std::fprintf(stderr, "densemap-upsample-eval: wrote the range images and %s/index.csv\n",
                 dir_.c_str());
    return {};
  }

 private:
  std::string dir_;
  std::string index_ = "scene,seed,pose,rows,cols,top_deg,bottom_deg,file\n";
  std::string error_;
};

}  // namespace

Expected<SimSums> scoreSimulated(const UpsampleEvalOptions& o, const Methods& methods,
                                 const RangeLayout& input, const std::vector<RangeLayout>& targets,
                                 tbb::task_arena& arena) {
  const auto seeds = parseNumberList(o.seeds_list);
  if (!seeds) return makeError("--seeds: " + seeds.error());
  const std::vector<std::string> scene_names = splitList(o.scenes_list);
  if (scene_names.empty() || seeds->empty()) return makeError("no scene or no seed to test on");
  ImageExport images(o.export_dir);
  if (auto ok = images.start(); !ok) return std::unexpected(ok.error());
  SimSums sums;
  const LidarModel input_sensor = sensorFor(input, o.max_range);
  Progress progress("densemap-upsample-eval: scan",
                    scene_names.size() * seeds->size() * static_cast<std::size_t>(o.scans));
  std::size_t done = 0;
  for (const std::string& name : scene_names) {
    for (const unsigned seed : *seeds) {
      auto scene = makeScene(name, seed);
      if (!scene) return std::unexpected(scene.error());
      const auto poses = trajectoryAlong(scene->waypoints, o.scans);
      for (std::size_t i = 0; i < poses.size(); ++i) {
        arena.execute([&] {
          const auto sparse = simulateScan(*scene->scene, input_sensor, poses[i], i, seed);
          const auto low = upsample::project(sparse.points, input);
          images.add(name, seed, i, low);
          for (std::size_t t = 0; t < targets.size(); ++t) {
            const auto dense =
                simulateScan(*scene->scene, sensorFor(targets[t], o.max_range), poses[i], i, seed);
            const auto truth = upsample::project(dense.points, targets[t]);
            images.add(name, seed, i, truth);
            const auto truth_points = upsample::backProject(truth);
            for (std::size_t m = 0; m < methods.list.size(); ++m) {
              sums[{m, t}].add(scoreUpsampling(low, truth, truth_points, methods.list[m],
                                               methods.model.get(), o.voxel));
            }
          }
        });
        progress.update(++done);
      }
    }
  }
  if (auto ok = images.finish(); !ok) return std::unexpected(ok.error());
  return sums;
}

}  // namespace densemap::tools
