#include "densemap/upsample/range_image.hpp"

#include "densemap/io/file_bytes.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <iomanip>
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
  if (beams_deg.empty()) return {};
  if (beams_deg.size() != static_cast<std::size_t>(rows)) {
    return makeError("the beam table has " + std::to_string(beams_deg.size()) + " elevations for " +
                     std::to_string(rows) + " rows");
  }
  for (std::size_t i = 1; i < beams_deg.size(); ++i) {
    if (!(beams_deg[i] < beams_deg[i - 1])) {
      return makeError("the beam table's elevations must decrease strictly (beam " +
                       std::to_string(i) + ")");
    }
  }
  if (beams_deg.front() != top_deg || beams_deg.back() != bottom_deg) {
    return makeError("the beam table's first and last elevations must be top and bottom");
  }
  return {};
}

Expected<RangeLayout> withBeams(std::vector<double> beams_deg, int cols) {
  if (beams_deg.size() < 2 || beams_deg.size() > 4096) {
    return makeError("a beam table needs 2..4096 elevations, not " +
                     std::to_string(beams_deg.size()));
  }
  RangeLayout l{.rows = static_cast<int>(beams_deg.size()),
                .cols = cols,
                .top_deg = beams_deg.front(),
                .bottom_deg = beams_deg.back(),
                .beams_deg = std::move(beams_deg)};
  if (auto ok = l.validate(); !ok) return std::unexpected(ok.error());
  return l;
}

Expected<std::vector<double>> readBeamTable(const std::string& path) {
  auto text = readFileBytes(path, std::uint64_t{1} << 20);
  if (!text) return makeError("beam table: " + text.error().message);
  std::istringstream in(*text);
  std::vector<double> beams;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    line = line.substr(0, line.find('#'));
    std::istringstream fields(line);
    double v = 0.0;
    if (!(fields >> v)) {
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      return makeError(path + ":" + std::to_string(number) + ": not an elevation: " + line);
    }
    std::string rest;
    if (fields >> rest || !std::isfinite(v) || v < -90.0 || v > 90.0) {
      return makeError(path + ":" + std::to_string(number) +
                       ": expected one elevation in [-90, 90] deg");
    }
    beams.push_back(v);
  }
  return beams;
}

std::string formatBeamTable(const std::vector<double>& beams_deg, const std::string& comment) {
  std::ostringstream out;
  std::istringstream lines(comment);
  for (std::string line; std::getline(lines, line);) out << "# " << line << '\n';
  out << std::fixed << std::setprecision(4);
  for (const double b : beams_deg) out << b << '\n';
  return out.str();
}

Expected<std::vector<double>> estimateBeams(const std::vector<PointCloud>& scans, int rows,
                                            double min_range_m) {
  if (rows < 2 || rows > 4096) return makeError("a beam table needs 2..4096 beams");
  std::vector<double> elevations;
  for (const PointCloud& scan : scans) {
    for (const Point3f& p : scan) {
      const double range = p.cast<double>().norm();
      if (!std::isfinite(range) || range <= min_range_m) continue;
      elevations.push_back(std::asin(p.z() / range) / kDegree);
    }
  }
  if (elevations.size() < 100 * static_cast<std::size_t>(rows)) {
    return makeError("too few returns (" + std::to_string(elevations.size()) + ") farther than " +
                     std::to_string(min_range_m) + " m to estimate " + std::to_string(rows) +
                     " beams");
  }
  std::sort(elevations.begin(), elevations.end(), std::greater<>());
  const std::size_t n = elevations.size();
  // Started evenly spread between the extreme elevations (robust quantiles): quantile starts
  // crowd the beams where the returns are dense and settle in a wrong local minimum.
  const double top = elevations[n / 200], bottom = elevations[n - 1 - n / 200];
  std::vector<double> centres(static_cast<std::size_t>(rows));
  for (int b = 0; b < rows; ++b) centres[b] = top - b * (top - bottom) / (rows - 1);
  // Lloyd's iterations on sorted data: each beam owns the run of elevations between the
  // midpoints to its neighbours.
  for (int iteration = 0; iteration < 200; ++iteration) {
    std::vector<double> next(centres.size());
    std::size_t from = 0;
    for (std::size_t b = 0; b < centres.size(); ++b) {
      std::size_t to = n;
      if (b + 1 < centres.size()) {
        const double cut = 0.5 * (centres[b] + centres[b + 1]);
        to = static_cast<std::size_t>(
            std::partition_point(elevations.begin() + static_cast<std::ptrdiff_t>(from),
                                 elevations.end(), [&](double e) { return e > cut; }) -
            elevations.begin());
      }
      double sum = 0.0;
      for (std::size_t i = from; i < to; ++i) sum += elevations[i];
      next[b] = to > from ? sum / static_cast<double>(to - from) : centres[b];
      from = to;
    }
    const bool settled = next == centres;
    centres = std::move(next);
    if (settled) break;
  }
  for (std::size_t b = 1; b < centres.size(); ++b) {
    if (!(centres[b] < centres[b - 1])) {
      return makeError("the returns do not separate into " + std::to_string(rows) + " beams");
    }
  }
  return centres;
}

Expected<RangeLayout> parseRangeLayout(const std::string& text, double top_deg, double bottom_deg) {
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
  if (beams_deg.empty()) return top_deg - row * (top_deg - bottom_deg) / (rows - 1);
  const int r0 = std::clamp(static_cast<int>(std::floor(row)), 0, rows - 2);
  return beams_deg[r0] + (row - r0) * (beams_deg[r0 + 1] - beams_deg[r0]);
}

double RangeLayout::azimuth(double col) const { return kTwoPi * col / cols; }

std::pair<double, double> RangeLayout::pixelOf(double elevation_deg, double az) const {
  double row = 0.0;
  if (beams_deg.empty()) {
    row = (top_deg - elevation_deg) * (rows - 1) / (top_deg - bottom_deg);
  } else {
    // The first beam at or below the elevation (the table decreases), then its upper segment.
    const auto below = std::lower_bound(beams_deg.begin(), beams_deg.end(), elevation_deg,
                                        [](double beam, double e) { return beam > e; });
    const int r1 = std::clamp(static_cast<int>(below - beams_deg.begin()), 1, rows - 1);
    row = r1 - 1 + (beams_deg[r1 - 1] - elevation_deg) / (beams_deg[r1 - 1] - beams_deg[r1]);
  }
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
  if (!l.beams_deg.empty()) {
    kept.beams_deg.clear();
    for (int r = 0; r < kept.rows; ++r) kept.beams_deg.push_back(l.beams_deg[r * n]);
  }
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
