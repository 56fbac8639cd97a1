#include "plots.hpp"

#include <array>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "densemap/io/file_bytes.hpp"

namespace densemap::tools {

Expected<void> writeRocSvg(const std::filesystem::path& path, const std::string& title,
                           const std::vector<RocSeries>& series) {
  constexpr double kLeft = 60, kTop = 40, kSize = 400;
  constexpr std::array<const char*, 6> kColours = {"#d62728", "#1f77b4", "#2ca02c",
                                                   "#ff7f0e", "#9467bd", "#8c564b"};
  const auto x = [&](double fpr) { return kLeft + fpr * kSize; };
  const auto y = [&](double tpr) { return kTop + (1.0 - tpr) * kSize; };
  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << kLeft + kSize + 200
      << "\" height=\"" << kTop + kSize + 60 << "\" font-family=\"sans-serif\" font-size=\"13\">\n"
      << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      << "<text x=\"" << kLeft << "\" y=\"24\" font-size=\"15\">" << title << "</text>\n"
      << "<rect x=\"" << kLeft << "\" y=\"" << kTop << "\" width=\"" << kSize << "\" height=\""
      << kSize << "\" fill=\"none\" stroke=\"black\"/>\n"
      << "<line x1=\"" << x(0) << "\" y1=\"" << y(0) << "\" x2=\"" << x(1) << "\" y2=\"" << y(1)
      << "\" stroke=\"#999\" stroke-dasharray=\"4 4\"/>\n";
  for (int i = 0; i <= 4; ++i) {
    const double v = i / 4.0;
    svg << "<text x=\"" << x(v) - 10 << "\" y=\"" << y(0) + 18 << "\">" << v << "</text>\n"
        << "<text x=\"" << kLeft - 35 << "\" y=\"" << y(v) + 4 << "\">" << v << "</text>\n";
  }
  svg << "<text x=\"" << x(0.5) - 60 << "\" y=\"" << y(0) + 40
      << "\">false positive rate</text>\n"
      << "<text transform=\"translate(" << kLeft - 45 << "," << y(0.5) + 50
      << ") rotate(-90)\">true positive rate</text>\n";
  for (std::size_t s = 0; s < series.size(); ++s) {
    const char* colour = kColours[s % kColours.size()];
    svg << "<polyline fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"2\" points=\"";
    // Thousands of points per curve are invisible at this size: keep one per 1/800 of a step.
    double last_x = -1, last_y = -1;
    for (const eval::RocPoint& p : series[s].points) {
      const double px = x(p.false_positive_rate), py = y(p.true_positive_rate);
      if (std::abs(px - last_x) + std::abs(py - last_y) < 0.5 && &p != &series[s].points.back()) {
        continue;
      }
      svg << px << ',' << py << ' ';
      last_x = px;
      last_y = py;
    }
    svg << "\"/>\n";
    char label[128];
    std::snprintf(label, sizeof(label), "%s (AUC %.3f)", series[s].name.c_str(), series[s].auc);
    const double ly = kTop + 20 + 22.0 * static_cast<double>(s);
    svg << "<line x1=\"" << kLeft + kSize + 15 << "\" y1=\"" << ly - 4 << "\" x2=\""
        << kLeft + kSize + 40 << "\" y2=\"" << ly - 4 << "\" stroke=\"" << colour
        << "\" stroke-width=\"3\"/>\n<text x=\"" << kLeft + kSize + 45 << "\" y=\"" << ly << "\">"
        << label << "</text>\n";
  }
  svg << "</svg>\n";
  return writeFileAtomically(path, svg.str());
}

}  // namespace densemap::tools
