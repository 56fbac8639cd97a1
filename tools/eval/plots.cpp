#include "plots.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "densemap/io/file_bytes.hpp"

namespace densemap::tools {
namespace {

/// A unit-square line plot: a polyline (and optionally a dot per point) per series, the
/// diagonal dashed, a legend of labels.
struct UnitPlot {
  std::string title, x_label, y_label;
  struct Series {
    std::string label;
    std::vector<std::pair<double, double>> points;
  };
  std::vector<Series> series;
  bool dots = false;
};

Expected<void> writeUnitPlotSvg(const std::filesystem::path& path, const UnitPlot& plot) {
  constexpr double kLeft = 60, kTop = 40, kSize = 400;
  constexpr std::array<const char*, 6> kColours = {"#d62728", "#1f77b4", "#2ca02c",
                                                   "#ff7f0e", "#9467bd", "#8c564b"};
  const auto x = [&](double v) { return kLeft + v * kSize; };
  const auto y = [&](double v) { return kTop + (1.0 - v) * kSize; };
  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << kLeft + kSize + 220
      << "\" height=\"" << kTop + kSize + 60 << "\" font-family=\"sans-serif\" font-size=\"13\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      << "<text x=\"" << kLeft << "\" y=\"24\" font-size=\"15\">" << plot.title << "</text>\n"
      << "<rect x=\"" << kLeft << "\" y=\"" << kTop << "\" width=\"" << kSize << "\" height=\""
      << kSize << "\" fill=\"none\" stroke=\"black\"/>\n"
      << "<line x1=\"" << x(0) << "\" y1=\"" << y(0) << "\" x2=\"" << x(1) << "\" y2=\"" << y(1)
      << "\" stroke=\"#999\" stroke-dasharray=\"4 4\"/>\n";
  for (int i = 0; i <= 4; ++i) {
    const double v = i / 4.0;
    svg << "<text x=\"" << x(v) - 10 << "\" y=\"" << y(0) + 18 << "\">" << v << "</text>\n"
        << "<text x=\"" << kLeft - 35 << "\" y=\"" << y(v) + 4 << "\">" << v << "</text>\n";
  }
  svg << "<text x=\"" << x(0.5) - 60 << "\" y=\"" << y(0) + 40 << "\">" << plot.x_label
      << "</text>\n"
      << "<text transform=\"translate(" << kLeft - 45 << "," << y(0.5) + 50 << ") rotate(-90)\">"
      << plot.y_label << "</text>\n";
  for (std::size_t s = 0; s < plot.series.size(); ++s) {
    const char* colour = kColours[s % kColours.size()];
    const auto& points = plot.series[s].points;
    svg << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"2\" points=\"";
    // Thousands of points per curve are invisible at this size: keep one per half pixel.
    double last_x = -1, last_y = -1;
    for (std::size_t i = 0; i < points.size(); ++i) {
      const double px = x(points[i].first), py = y(points[i].second);
      if (std::abs(px - last_x) + std::abs(py - last_y) < 0.5 && i + 1 != points.size()) continue;
      svg << px << ',' << py << ' ';
      last_x = px;
      last_y = py;
    }
    svg << "\"/>\n";
    for (std::size_t i = 0; plot.dots && i < points.size(); ++i) {
      svg << "<circle cx=\"" << x(points[i].first) << "\" cy=\"" << y(points[i].second)
          << "\" r=\"3\" fill=\"" << colour << "\"/>\n";
    }
    const double ly = kTop + 20 + 22.0 * static_cast<double>(s);
    svg << "<line x1=\"" << kLeft + kSize + 15 << "\" y1=\"" << ly - 4 << "\" x2=\""
        << kLeft + kSize + 40 << "\" y2=\"" << ly - 4 << "\" stroke=\"" << colour
        << "\" stroke-width=\"3\"/>\n<text x=\"" << kLeft + kSize + 45 << "\" y=\"" << ly << "\">"
        << plot.series[s].label << "</text>\n";
  }
  svg << "</svg>\n";
  return writeFileAtomically(path, svg.str());
}

std::string labelled(const std::string& name, const char* format, double value) {
  char label[160];
  std::snprintf(label, sizeof(label), format, name.c_str(), value);
  return label;
}

}  // namespace

Expected<void> writeRocSvg(const std::filesystem::path& path, const std::string& title,
                           const std::vector<RocSeries>& series) {
  UnitPlot plot{title, "false positive rate", "true positive rate", {}, false};
  for (const RocSeries& s : series) {
    UnitPlot::Series line{labelled(s.name, "%s (AUC %.3f)", s.auc), {}};
    for (const eval::RocPoint& p : s.points) {
      line.points.emplace_back(p.false_positive_rate, p.true_positive_rate);
    }
    plot.series.push_back(std::move(line));
  }
  return writeUnitPlotSvg(path, plot);
}

Expected<void> writeReliabilitySvg(const std::filesystem::path& path, const std::string& title,
                                   const std::vector<ReliabilitySeries>& series) {
  UnitPlot plot{title, "predicted probability", "observed occupied share", {}, true};
  for (const ReliabilitySeries& s : series) {
    UnitPlot::Series line{labelled(s.name, "%s (ECE %.3f)", s.ece), {}};
    for (const eval::ReliabilityBin& b : s.bins) {
      if (b.count > 0) line.points.emplace_back(b.mean_predicted, b.observed);
    }
    plot.series.push_back(std::move(line));
  }
  return writeUnitPlotSvg(path, plot);
}

}  // namespace densemap::tools
