#include "densemap/upsample/range_image.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace densemap::upsample {

namespace {
constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kDegree = std::numbers::pi / 180.0;
}  // namespace

Expected<void> RangeLayout::validate() const {
  if (rows < 2 || rows > 4096) return makeError("range image rows must be in 2..4096");
  if (cols < 4 || cols > 65536) return makeError("range image columns must be in 4..65536");
  if (!(top_deg > bottom_deg) || top_deg > 90.0 || bottom_deg < -90.0) {
    return makeError("range image field of view must satisfy -90 <= bottom < top <= 90 deg");
  }
  return {};
}

Expected<RangeLayout> parseRangeLayout(const std::string& text, double top_deg,
                                       double bottom_deg) {
  RangeLayout l{.top_deg = top_deg, .bottom_deg = bottom_deg};
  char x = 0;
  std::istringstream in(text);
  if (!(in >> l.rows >> x >> l.cols) || x != 'x' || !in.eof()) {
    return makeError("grid '" + text + "' is not ROWSxCOLS (e.g. 64x1024)");
  }
  if (auto ok = l.validate(); !ok) return std::unexpected(ok.error());
  return l;
}

double RangeLayout::elevationDeg(double row) const {
  return top_deg - row * (top_deg - bottom_deg) / (rows - 1);
}

double RangeLayout::azimuth(double col) const { return kTwoPi * col / cols; }

std::pair<double, double> RangeLayout::pixelOf(double elevation_deg, double az) const {
  const double row = (top_deg - elevation_deg) * (rows - 1) / (top_deg - bottom_deg);
  double col = az / kTwoPi * cols;
  col = std::fmod(col, static_cast<double>(cols));
  if (col < 0.0) col += cols;
  return {row, col};
}

std::pair<double, double> RangeLayout::toLayout(const RangeLayout& other, double row,
                                                double col) const {
  return other.pixelOf(elevationDeg(row), azimuth(col));
}

std::size_t RangeImage::returns() const {
  std::size_t n = 0;
  for (const float r : range) n += r > 0.0F ? 1 : 0;
  return n;
}

RangeImage project(const PointCloud& points_sensor, const RangeLayout& layout,
                   ProjectionStats* stats) {
  RangeImage image(layout);
  ProjectionStats s;
  for (const Point3f& p : points_sensor) {
    ++s.points;
    const double x = p.x(), y = p.y(), z = p.z();
    const double range = std::sqrt(x * x + y * y + z * z);
    if (!std::isfinite(range) || range <= 0.0) {
      ++s.outside_fov;
      continue;
    }
    const auto [row_f, col_f] = layout.pixelOf(std::asin(z / range) / kDegree, std::atan2(y, x));
    const long row = std::lround(row_f);
    long col = std::lround(col_f);
    if (col == layout.cols) col = 0;
    if (row < 0 || row >= layout.rows) {
      ++s.outside_fov;
      continue;
    }
    float& pixel = image.at(static_cast<int>(row), static_cast<int>(col));
    if (pixel > 0.0F) {
      ++s.collisions;
      if (pixel <= range) continue;
    }
    pixel = static_cast<float>(range);
  }
  if (stats != nullptr) *stats = s;
  return image;
}

Expected<RangeError> compareRanges(const RangeImage& predicted, const RangeImage& truth) {
  if (predicted.layout.rows != truth.layout.rows || predicted.layout.cols != truth.layout.cols) {
    return makeError("range images of different sizes cannot be compared");
  }
  RangeError e;
  double sum = 0.0;
  std::size_t true_returns = 0;
  for (std::size_t i = 0; i < truth.range.size(); ++i) {
    if (!(truth.range[i] > 0.0F)) continue;
    ++true_returns;
    if (!(predicted.range[i] > 0.0F)) continue;
    sum += std::abs(static_cast<double>(predicted.range[i]) - truth.range[i]);
    ++e.pixels;
  }
  if (e.pixels > 0) e.mae = sum / static_cast<double>(e.pixels);
  if (true_returns > 0) e.coverage = static_cast<double>(e.pixels) / true_returns;
  return e;
}

RangeImage keepEveryNthRow(const RangeImage& image, int n) {
  const RangeLayout& l = image.layout;
  n = std::max(n, 1);
  RangeLayout kept = l;
  kept.rows = (l.rows - 1) / n + 1;
  kept.bottom_deg = l.elevationDeg((kept.rows - 1) * n);
  RangeImage out(kept);
  for (int r = 0; r < kept.rows; ++r) {
    for (int c = 0; c < l.cols; ++c) out.at(r, c) = image.at(r * n, c);
  }
  return out;
}

PointCloud backProject(const RangeImage& image) {
  PointCloud points;
  const RangeLayout& l = image.layout;
  for (int r = 0; r < l.rows; ++r) {
    const double e = l.elevationDeg(r) * kDegree;
    for (int c = 0; c < l.cols; ++c) {
      const float range = image.at(r, c);
      if (!(range > 0.0F)) continue;
      const double a = l.azimuth(c);
      points.emplace_back(static_cast<float>(range * std::cos(e) * std::cos(a)),
                          static_cast<float>(range * std::cos(e) * std::sin(a)),
                          static_cast<float>(range * std::sin(e)));
    }
  }
  return points;
}

}  // namespace densemap::upsample
