#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include "densemap/cli/lists.hpp"
#include "densemap/cli/progress.hpp"
#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"
#include "upsample_eval.hpp"

namespace densemap::tools {
namespace {

/// The real dataset's scans [first, end) as sensor-frame clouds.
struct RealScans {
  std::unique_ptr<ScanSource> source;
  std::string path;
  std::size_t first = 0, end = 0;

  [[nodiscard]] Expected<PointCloud> at(std::size_t i) const {
    auto scan = source->load(i);
    if (!scan) return std::unexpected(scan.error());
    if (scan->frame != PointFrame::kSensor) {
      return makeError(path +
                       " stores world-frame points: range images need sensor-frame "
                       "scans");
    }
    return std::move(scan->points);
  }
};

Expected<std::vector<int>> parseReduces(const std::string& text) {
  std::vector<int> reduces;
  for (const std::string& item : splitList(text)) {
    const auto n = parseNumberList(item);
    if (!n || n->size() != 1 || n->front() < 2 || n->front() > 16) {
      return makeError("--reduce: '" + item + "' is not a number in 2..16");
    }
    reduces.push_back(static_cast<int>(n->front()));
  }
  if (reduces.empty()) return makeError("--reduce lists nothing");
  return reduces;
}

Expected<std::vector<Split>> parseSplits(const std::string& text, std::size_t first,
                                         std::size_t end) {
  if (text.empty()) return std::vector<Split>{{"all", first, end - 1}};
  std::vector<Split> splits;
  for (const std::string& item : splitList(text)) {
    const auto split = parseSplit(item);
    if (!split) return makeError("--real-splits: '" + item + "' is not NAME:FIRST-LAST");
    splits.push_back(*split);
  }
  return splits;
}

/// --estimate-beams: the beam table from the scans, written to its file; returns its path.
Expected<std::string> estimateBeamTable(const UpsampleEvalOptions& o, const RealScans& scans,
                                        int rows) {
  std::vector<PointCloud> clouds;
  for (std::size_t i = scans.first; i < scans.end; ++i) {
    auto points = scans.at(i);
    if (!points) return std::unexpected(points.error());
    clouds.push_back(std::move(*points));
  }
  auto beams = upsample::estimateBeams(clouds, rows);
  if (!beams) return makeError("--estimate-beams: " + beams.error().message);
  std::ostringstream comment;
  comment << "Beam table of " << o.real_path << " (scans " << scans.first << ".." << scans.end - 1
          << "), estimated by densemap-upsample-eval --estimate-beams:\nelevations, deg, "
             "top beam first";
  if (auto ok = writeFileAtomically(o.estimate_beams_path,
                                    upsample::formatBeamTable(*beams, comment.str()));
      !ok) {
    return std::unexpected(ok.error());
  }
  std::fprintf(stderr, "densemap-upsample-eval: wrote the beam table %s\n",
               o.estimate_beams_path.c_str());
  return o.estimate_beams_path;
}

/// The real sensor's layout: --real-grid, with the beam table of `beams_path` when given.
Expected<RangeLayout> realLayout(const RangeLayout& grid, const std::string& beams_path) {
  if (beams_path.empty()) return grid;
  auto beams = upsample::readBeamTable(beams_path);
  if (!beams) return std::unexpected(beams.error());
  auto with = upsample::withBeams(std::move(*beams), grid.cols);
  if (!with) return makeError(beams_path + ": " + with.error().message);
  if (with->rows != grid.rows) {
    return makeError(beams_path + " has " + std::to_string(with->rows) +
                     " beams but --real-grid has " + std::to_string(grid.rows) + " rows");
  }
  return std::move(*with);
}

/// --export-real: every real scan's full range image and the beam table, for tools/iln.
class RealExport {
 public:
  RealExport(const UpsampleEvalOptions& o, const RangeLayout& layout)
      : o_(o), layout_(layout), beams_file_("beams_" + std::to_string(layout.rows) + ".txt") {}
  [[nodiscard]] Expected<void> start() const {
    if (o_.export_real_dir.empty()) return {};
    std::error_code ec;
    std::filesystem::create_directories(o_.export_real_dir, ec);
    if (ec) return makeError("cannot create " + o_.export_real_dir + ": " + ec.message());
    std::vector<double> beams = layout_.beams_deg;
    for (int r = 0; beams.empty() && r < layout_.rows; ++r)
      beams.push_back(layout_.elevationDeg(r));
    return writeFileAtomically(std::filesystem::path(o_.export_real_dir) / beams_file_,
                               upsample::formatBeamTable(beams, "beams of " + o_.real_path));
  }
  [[nodiscard]] Expected<void> add(std::size_t i, const upsample::RangeImage& truth) {
    if (o_.export_real_dir.empty()) return {};
    const std::string file = "real_" + std::to_string(i) + ".f32";
    std::ostringstream row;
    row << std::setprecision(10) << "real," << i << ",0," << layout_.rows << ',' << layout_.cols
        << ',' << layout_.top_deg << ',' << layout_.bottom_deg << ',' << file << ',' << beams_file_
        << '\n';
    index_ += row.str();
    return writeFileAtomically(std::filesystem::path(o_.export_real_dir) / file,
                               std::string(reinterpret_cast<const char*>(truth.range.data()),
                                           truth.range.size() * sizeof(float)));
  }
  [[nodiscard]] Expected<void> finish() const {
    if (o_.export_real_dir.empty()) return {};
    if (auto ok =
            writeFileAtomically(std::filesystem::path(o_.export_real_dir) / "index.csv", index_);
        !ok) {
      return ok;
    }
    std::fprintf(stderr, "densemap-upsample-eval: wrote the real range images and %s/index.csv\n",
                 o_.export_real_dir.c_str());
    return {};
  }

 private:
  const UpsampleEvalOptions& o_;
  const RangeLayout& layout_;
  std::string beams_file_;
  std::string index_ = "scene,seed,pose,rows,cols,top_deg,bottom_deg,file,beams\n";
};

}  // namespace

Expected<RealResults> scoreReal(const UpsampleEvalOptions& o, const Methods& methods,
                                tbb::task_arena& arena) {
  RealResults r;
  auto reduces = parseReduces(o.reduce_text);
  if (!reduces) return std::unexpected(reduces.error());
  r.reduces = std::move(*reduces);
  auto grid = upsample::parseRangeLayout(o.real_layout_text, o.real_top, o.real_bottom);
  if (!grid) return makeError("--real-grid: " + grid.error().message);
  auto source = openScanSource(o.real_path);
  if (!source) return std::unexpected(source.error());
  RealScans scans{std::move(*source), o.real_path, o.real_first, 0};
  const std::size_t total = scans.source->size();
  if (o.real_first >= total) return makeError("--real-first is past the data's scans");
  scans.end = o.real_limit == 0 ? total : std::min(total, o.real_first + o.real_limit);
  auto splits = parseSplits(o.real_splits_text, scans.first, scans.end);
  if (!splits) return std::unexpected(splits.error());
  r.splits = std::move(*splits);
  std::string beams_path = o.real_beams_path;
  if (!o.estimate_beams_path.empty()) {
    auto estimated = estimateBeamTable(o, scans, grid->rows);
    if (!estimated) return std::unexpected(estimated.error());
    beams_path = *estimated;
  }
  auto layout = realLayout(*grid, beams_path);
  if (!layout) return std::unexpected(layout.error());
  r.layout = std::move(*layout);
  RealExport exported(o, r.layout);
  if (auto ok = exported.start(); !ok) return std::unexpected(ok.error());
  Progress progress("densemap-upsample-eval: real scan", scans.end - scans.first);
  std::size_t outside = 0, collisions = 0, points = 0;
  for (std::size_t i = scans.first; i < scans.end; ++i) {
    auto scan = scans.at(i);
    if (!scan) return std::unexpected(scan.error());
    upsample::ProjectionStats stats;
    const auto truth = upsample::project(*scan, r.layout, &stats);
    outside += stats.outside_fov;
    collisions += stats.collisions;
    points += stats.points;
    if (auto ok = exported.add(i, truth); !ok) return std::unexpected(ok.error());
    // Each (reduction, method) is scored once and counted in every split holding the scan.
    std::vector<std::size_t> in_splits;
    for (std::size_t sp = 0; sp < r.splits.size(); ++sp) {
      if (i >= r.splits[sp].first && i <= r.splits[sp].last) in_splits.push_back(sp);
    }
    if (!in_splits.empty()) {
      const auto truth_points = upsample::backProject(truth);
      for (std::size_t n = 0; n < r.reduces.size(); ++n) {
        const auto sparse = upsample::keepEveryNthRow(truth, r.reduces[n]);
        arena.execute([&] {
          for (std::size_t m = 0; m < methods.list.size(); ++m) {
            const Score score = scoreUpsampling(sparse, truth, truth_points, methods.list[m],
                                                methods.model.get(), o.voxel);
            for (const std::size_t sp : in_splits) r.sums[{sp, n, m}].add(score);
          }
        });
      }
    }
    progress.update(i + 1 - scans.first);
  }
  std::fprintf(stderr,
               "densemap-upsample-eval: real scans projected: %zu points, %zu outside the "
               "field of view, %zu sharing a pixel with a nearer one\n",
               points, outside, collisions);
  if (auto ok = exported.finish(); !ok) return std::unexpected(ok.error());
  return r;
}

}  // namespace densemap::tools
