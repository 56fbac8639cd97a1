#include <charconv>
#include <chrono>
#include <string_view>

#include "densemap/geometry/percentile.hpp"
#include "upsample_eval.hpp"

namespace densemap::tools {

LidarModel sensorFor(const RangeLayout& layout, double max_range) {
  LidarModel m;
  m.name = std::to_string(layout.rows) + "x" + std::to_string(layout.cols);
  for (int r = 0; r < layout.rows; ++r) m.elevations_deg.push_back(layout.elevationDeg(r));
  m.columns = layout.cols;
  m.min_range_m = 0.5;
  m.max_range_m = max_range;
  return m;
}

Score scoreUpsampling(const upsample::RangeImage& input, const upsample::RangeImage& truth,
                      const PointCloud& truth_points, upsample::Interpolation method,
                      const upsample::IlnModel* model, double voxel) {
  const auto t0 = std::chrono::steady_clock::now();
  const auto predicted = upsample::upsample(input, truth.layout, method, model);
  Score score;
  score.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  score.range = *upsample::compareRanges(predicted, truth);
  score.points = eval::comparePointSets(upsample::backProject(predicted), truth_points, voxel);
  return score;
}

double Sum::msP50() const { return percentile(ms_each, 0.5); }

void Sum::add(const Score& s) {
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

}  // namespace densemap::tools
