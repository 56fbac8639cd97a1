#include "densemap/load/chart.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>

#include "densemap/io/png_writer.hpp"

namespace densemap::load {
namespace {

// 5x7 glyphs, one byte per row, bit 4 the leftmost pixel.
struct Glyph {
  char c;
  std::uint8_t rows[7];
};
constexpr Glyph kFont[] = {
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}}, {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}}, {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}}, {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}}, {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}}, {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'A', {0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}}, {'B', {0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E}},
    {'C', {0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E}}, {'D', {0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C}},
    {'E', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F}}, {'F', {0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10}},
    {'G', {0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F}}, {'H', {0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11}},
    {'I', {0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E}}, {'J', {0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},
    {'K', {0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11}}, {'L', {0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F}},
    {'M', {0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11}}, {'N', {0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11}},
    {'O', {0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}}, {'P', {0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10}},
    {'Q', {0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D}}, {'R', {0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11}},
    {'S', {0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E}}, {'T', {0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04}},
    {'U', {0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E}}, {'V', {0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}}, {'X', {0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11}},
    {'Y', {0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04}}, {'Z', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F}},
    {'.', {0, 0, 0, 0, 0, 0x0C, 0x0C}},                {'/', {0, 0x01, 0x02, 0x04, 0x08, 0x10, 0}},
    {'%', {0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03}}, {'(', {0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02}},
    {')', {0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08}}, {',', {0, 0, 0, 0, 0x0C, 0x04, 0x08}},
    {':', {0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0}},          {'-', {0, 0, 0, 0x1F, 0, 0, 0}},
    {'+', {0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0}},       {'=', {0, 0, 0x1F, 0, 0x1F, 0, 0}},
};

class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), rgb_(static_cast<std::size_t>(w) * h * 3, 255) {}
  void dot(int x, int y, const std::array<std::uint8_t, 3>& c) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_) return;
    std::copy(c.begin(), c.end(), rgb_.begin() + (static_cast<std::ptrdiff_t>(y) * w_ + x) * 3);
  }
  void line(int x0, int y0, int x1, int y1, const std::array<std::uint8_t, 3>& c) {
    const int n = std::max(std::abs(x1 - x0), std::abs(y1 - y0));
    for (int i = 0; i <= n; ++i) {
      const double t = n == 0 ? 0 : static_cast<double>(i) / n;
      const int x = static_cast<int>(std::lround(x0 + t * (x1 - x0)));
      const int y = static_cast<int>(std::lround(y0 + t * (y1 - y0)));
      dot(x, y, c);
      dot(x, y + 1, c);  // two pixels thick
    }
  }
  /// Text at (x, y) top-left, 2x scaled glyphs; returns the x after it.
  int text(int x, int y, const std::string& s, const std::array<std::uint8_t, 3>& c) {
    for (const char raw : s) {
      const char ch = static_cast<char>(std::toupper(static_cast<unsigned char>(raw)));
      for (const Glyph& g : kFont) {
        if (g.c != ch) continue;
        for (int r = 0; r < 7; ++r) {
          for (int b = 0; b < 5; ++b) {
            if ((g.rows[r] >> (4 - b) & 1) == 0) continue;
            for (int k = 0; k < 4; ++k) dot(x + 2 * b + k % 2, y + 2 * r + k / 2, c);
          }
        }
      }
      x += 12;
    }
    return x;
  }
  [[nodiscard]] const std::vector<std::uint8_t>& rgb() const { return rgb_; }

 private:
  int w_, h_;
  std::vector<std::uint8_t> rgb_;
};

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, v >= 100 ? "%.0f" : (v >= 10 ? "%.1f" : "%.2f"), v);
  return buf;
}

}  // namespace

Expected<void> writeChart(const std::filesystem::path& file, const std::string& title,
                          const std::string& x_label, const std::vector<double>& x,
                          const std::vector<Panel>& panels) {
  constexpr int kWidth = 1200, kPanel = 220, kTop = 40, kLeft = 90, kRight = 20, kGap = 50;
  const int height = kTop + static_cast<int>(panels.size()) * (kPanel + kGap) + 30;
  Canvas canvas(kWidth, height);
  const std::array<std::uint8_t, 3> black{0, 0, 0}, grey{200, 200, 200};
  canvas.text(kLeft, 10, title, black);
  const double x0 = x.empty() ? 0 : x.front();
  const double x1 = x.empty() ? 1 : std::max(x.back(), x0 + 1e-9);
  const int plot_w = kWidth - kLeft - kRight;
  auto px = [&](double v) { return kLeft + static_cast<int>((v - x0) / (x1 - x0) * plot_w); };
  for (std::size_t p = 0; p < panels.size(); ++p) {
    const int top = kTop + static_cast<int>(p) * (kPanel + kGap) + 24;
    const int bottom = top + kPanel;
    double ymax = 0;
    for (const Series& s : panels[p].series) {
      for (const double v : s.y) {
        if (std::isfinite(v)) ymax = std::max(ymax, v);
      }
    }
    ymax = ymax > 0 ? ymax * 1.1 : 1.0;
    int tx = canvas.text(kLeft, top - 22, panels[p].title, black) + 12;
    for (const Series& s : panels[p].series) tx = canvas.text(tx, top - 22, s.label, s.colour) + 12;
    for (int i = 1; i <= 4; ++i) {  // grid lines at quarters
      const int y = bottom - i * kPanel / 4;
      for (int gx = kLeft; gx < kWidth - kRight; gx += 4) canvas.dot(gx, y, grey);
    }
    canvas.line(kLeft, top, kLeft, bottom, black);
    canvas.line(kLeft, bottom, kWidth - kRight, bottom, black);
    canvas.text(4, top, number(ymax), black);
    canvas.text(4, top + kPanel / 2 - 7, number(ymax / 2), black);
    canvas.text(4, bottom - 14, "0", black);
    auto py = [&](double v) { return bottom - static_cast<int>(v / ymax * kPanel); };
    for (const Series& s : panels[p].series) {
      for (std::size_t i = 0; i + 1 < std::min(s.y.size(), x.size()); ++i) {
        if (!std::isfinite(s.y[i]) || !std::isfinite(s.y[i + 1])) continue;
        canvas.line(px(x[i]), py(s.y[i]), px(x[i + 1]), py(s.y[i + 1]), s.colour);
      }
      if (s.y.size() == 1 && !x.empty() && std::isfinite(s.y[0])) {
        for (int k = -3; k <= 3; ++k) canvas.line(px(x[0]) + k, py(s.y[0]) - 3, px(x[0]) + k, py(s.y[0]) + 3, s.colour);
      }
    }
    canvas.text(kLeft - 4, bottom + 6, number(x0), black);
    canvas.text(kWidth - kRight - 60, bottom + 6, number(x1), black);
    canvas.text(kLeft + plot_w / 2 - 6 * static_cast<int>(x_label.size()), bottom + 6, x_label,
                black);
  }
  return writePng(file, kWidth, height, canvas.rgb());
}

}  // namespace densemap::load
