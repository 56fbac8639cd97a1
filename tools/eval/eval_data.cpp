#include "eval_data.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "densemap/io/png_writer.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/kernel/kernel_map.hpp"
#include "densemap/upsample/interpolation.hpp"

namespace densemap::tools {

void split(const PointCloud& points, const Point3f& origin, std::uint64_t seed, std::uint64_t scan,
           double resolution, EvalScan& out, std::vector<TestPoint>& tests) {
  out.origin = origin;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::uint64_t key = seed * 0x9E3779B97F4A7C15ULL ^ scan * 0xC2B2AE3D27D4EB4FULL ^ i;
    if (kernel::uniformFromCounter(key) >= 0.2) {
      out.train.push_back(points[i]);
      continue;
    }
    tests.push_back({points[i], true});
    const Point3f ray = points[i] - origin;
    const double length = ray.norm();
    if (length <= 2.0 * resolution) continue;
    const double t = kernel::uniformFromCounter(key ^ 0x5555555555555555ULL) *
                     (length - 2.0 * resolution) / length;
    tests.push_back({origin + static_cast<float>(t) * ray, false});
  }
}

namespace {

SliceFrame frameOf(const EvalData& d, double resolution) {
  SliceFrame frame;
  Eigen::AlignedBox3f box;
  for (std::size_t i = 0; i < d.clouds.size(); ++i) {
    box.extend(d.origins[i]);
    for (const Point3f& p : d.clouds[i]) box.extend(p);
  }
  if (!box.isEmpty()) {
    frame.x0 = std::floor(box.min().x() / resolution) * resolution;
    frame.y0 = std::floor(box.min().y() / resolution) * resolution;
    frame.cols = std::min(4000, static_cast<int>((box.max().x() - frame.x0) / resolution) + 1);
    frame.rows = std::min(4000, static_cast<int>((box.max().y() - frame.y0) / resolution) + 1);
  }
  return frame;
}

}  // namespace

Expected<EvalData> loadEvalData(const EvalOptions& o) {
  auto source = openScanSource(o.data);
  if (!source) return std::unexpected(source.error());
  const std::size_t total = (*source)->size();
  if (o.first >= total) {
    return makeError("--first is past the dataset's " + std::to_string(total) + " scans");
  }
  const std::size_t end = o.limit == 0 ? total : std::min(total, o.first + o.limit);
  auto densify = upsample::upsampleFromFlags(o.upsample_method, o.upsample_input,
                                             o.upsample_output, o.fov_top, o.fov_bottom,
                                             o.upsample_model);
  if (!densify) return std::unexpected(densify.error());
  EvalData d;
  std::size_t rejected = 0;
  for (std::size_t i = o.first; i < end; ++i) {
    auto scan = (*source)->load(i);
    if (!scan) return std::unexpected(scan.error());
    if (*densify) {
      if (scan->frame != PointFrame::kSensor) {
        return makeError("--upsample needs sensor-frame scans; " + o.data +
                         " stores world-frame points");
      }
      scan->points = upsample::upsamplePoints(scan->points, **densify);
    }
    d.clouds.push_back(scan->pointsWorld());
    rejected += removeNonFinite(d.clouds.back());
    d.origins.push_back(scan->originWorld());
  }
  if (rejected > 0)
    std::fprintf(stderr, "densemap-eval: dropped %zu non-finite points\n", rejected);
  d.frame = frameOf(d, o.resolution);
  return d;
}

Expected<void> writeSlice(const EvalOptions& o, const SliceFrame& f, const std::string& name,
                          const std::function<double(const Point3f&)>& p) {
  const std::string path = o.slice_prefix + "_" + name + ".png";
  const int scale = std::clamp(800 / std::max({f.cols, f.rows, 1}), 1, 8);
  const int width = f.cols * scale, height = f.rows * scale;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(width) * height * 3);
  for (int r = 0; r < f.rows; ++r) {
    for (int c = 0; c < f.cols; ++c) {
      const Point3f x(static_cast<float>(f.x0 + (c + 0.5) * o.resolution),
                      static_cast<float>(f.y0 + (f.rows - r - 0.5) * o.resolution),
                      static_cast<float>(o.slice_z));
      const auto v = static_cast<std::uint8_t>(std::lround(255.0 * (1.0 - p(x))));
      for (int dy = 0; dy < scale; ++dy) {
        for (int dx = 0; dx < scale; ++dx) {
          const auto at = 3 * (static_cast<std::size_t>(r * scale + dy) * width + c * scale + dx);
          rgb[at] = rgb[at + 1] = rgb[at + 2] = v;
        }
      }
    }
  }
  if (auto ok = writePng(path, width, height, rgb); !ok) return ok;
  std::fprintf(stderr, "densemap-eval: wrote %s\n", path.c_str());
  return {};
}

Expected<std::vector<TestPoint>> oracleTests(const EvalOptions& o, const SliceFrame& frame) {
  const auto labels =
      readOracleLabels(o.labels_path.empty() ? oracleLabelsPath(o.data, o.resolution)
                                             : std::filesystem::path(o.labels_path),
                       o.resolution);
  if (!labels) return std::unexpected(labels.error());
  const VoxelGrid grid(o.resolution);
  std::vector<TestPoint> tests;
  for (const LabelledVoxel& v : *labels) {
    tests.push_back({Point3f(static_cast<float>(grid.keyToCoord(v.key.x)),
                             static_cast<float>(grid.keyToCoord(v.key.y)),
                             static_cast<float>(grid.keyToCoord(v.key.z))),
                     v.occupied});
  }
  if (tests.empty()) return makeError("the oracle labels hold no voxel");
  if (!o.slice_prefix.empty()) {
    std::unordered_map<std::uint64_t, bool> truth;
    for (const LabelledVoxel& v : *labels) truth[v.key.packed()] = v.occupied;
    auto ok = writeSlice(o, frame, "oracle", [&](const Point3f& x) {
      const auto key = grid.pointToKey(x);
      const auto it = key ? truth.find(key->packed()) : truth.end();
      return it == truth.end() ? 0.5 : (it->second ? 1.0 : 0.0);
    });
    if (!ok) return std::unexpected(ok.error());
  }
  return tests;
}

}  // namespace densemap::tools
