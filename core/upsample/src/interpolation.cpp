#include "densemap/upsample/interpolation.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "densemap/upsample/iln.hpp"

namespace densemap::upsample {

std::string_view interpolationName(Interpolation method) {
  switch (method) {
    case Interpolation::kNearest: return "nearest";
    case Interpolation::kBilinear: return "bilinear";
    case Interpolation::kIln: return "iln";
  }
  return "?";
}

Expected<Interpolation> parseInterpolation(std::string_view name) {
  if (name == "nearest") return Interpolation::kNearest;
  if (name == "bilinear") return Interpolation::kBilinear;
  if (name == "iln") return Interpolation::kIln;
  return makeError("unknown interpolation '" + std::string(name) +
                   "' (nearest, bilinear or iln)");
}

Neighbourhood neighbourhood(const RangeImage& input, double row, double col) {
  const RangeLayout& l = input.layout;
  row = std::clamp(row, 0.0, static_cast<double>(l.rows - 1));
  const int r0 = std::min(static_cast<int>(std::floor(row)), l.rows - 2);
  const double c_floor = std::floor(col);
  const int c0 = ((static_cast<int>(c_floor) % l.cols) + l.cols) % l.cols;
  Neighbourhood n{};
  n.d_row = row - r0;
  n.d_col = col - c_floor;
  for (int t = 0; t < 4; ++t) {
    n.row[t] = r0 + t / 2;
    n.col[t] = (c0 + t % 2) % l.cols;
    n.range[t] = input.at(n.row[t], n.col[t]);
    n.weight[t] = (t / 2 == 0 ? 1.0 - n.d_row : n.d_row) * (t % 2 == 0 ? 1.0 - n.d_col : n.d_col);
  }
  return n;
}

float interpolate(const RangeImage& input, double row, double col, Interpolation method) {
  if (method == Interpolation::kIln) std::abort();  // a caller's bug: see the header
  const Neighbourhood n = neighbourhood(input, row, col);
  if (method == Interpolation::kNearest) {
    const int t = (n.d_row < 0.5 ? 0 : 2) + (n.d_col < 0.5 ? 0 : 1);
    return n.range[t];
  }
  double sum = 0.0, weight = 0.0;
  for (int t = 0; t < 4; ++t) {
    if (n.range[t] > 0.0F) {
      sum += n.weight[t] * n.range[t];
      weight += n.weight[t];
    }
  }
  return weight > 1e-9 ? static_cast<float>(sum / weight) : 0.0F;
}

RangeImage upsample(const RangeImage& input, const RangeLayout& output, Interpolation method,
                    const IlnModel* iln) {
  if (method == Interpolation::kIln) {
    if (iln == nullptr) std::abort();  // a caller's bug: UpsampleOptions::validate catches it
    return iln->upsample(input, output);
  }
  RangeImage out(output);
  tbb::parallel_for(tbb::blocked_range<int>(0, output.rows),
                    [&](const tbb::blocked_range<int>& rows) {
                      for (int r = rows.begin(); r != rows.end(); ++r) {
                        for (int c = 0; c < output.cols; ++c) {
                          const auto [row, col] = output.toLayout(input.layout, r, c);
                          out.at(r, c) = interpolate(input, row, col, method);
                        }
                      }
                    });
  return out;
}

Expected<void> UpsampleOptions::validate() const {
  if (auto ok = input.validate(); !ok) return makeError("upsample input: " + ok.error().message);
  if (auto ok = output.validate(); !ok) {
    return makeError("upsample output: " + ok.error().message);
  }
  if (input.top_deg != output.top_deg || input.bottom_deg != output.bottom_deg) {
    return makeError("upsample input and output must share the field of view");
  }
  if (method == Interpolation::kIln && !iln) return makeError("upsample method iln needs a model");
  return {};
}

Expected<UpsampleOptions> makeUpsampleOptions(std::string_view method, const RangeLayout& input,
                                              const RangeLayout& output,
                                              const std::string& model_path) {
  auto parsed = parseInterpolation(method);
  if (!parsed) return std::unexpected(parsed.error());
  UpsampleOptions options{.input = input, .output = output, .method = *parsed, .iln = nullptr};
  if (*parsed == Interpolation::kIln) {
    auto model = IlnModel::load(model_path);
    if (!model) return std::unexpected(model.error());
    options.iln = std::make_shared<const IlnModel>(std::move(*model));
  }
  if (auto ok = options.validate(); !ok) return std::unexpected(ok.error());
  return options;
}

PointCloud upsamplePoints(const PointCloud& points_sensor, const UpsampleOptions& options,
                          ProjectionStats* stats) {
  return backProject(upsample(project(points_sensor, options.input, stats), options.output,
                              options.method, options.iln.get()));
}

Expected<std::optional<UpsampleOptions>> upsampleFromFlags(
    const std::string& method, const std::string& input, const std::string& output,
    double top_deg, double bottom_deg, const std::string& model_path) {
  if (method.empty()) return std::nullopt;
  auto in = parseRangeLayout(input, top_deg, bottom_deg);
  if (!in) return makeError("--upsample-input: " + in.error().message);
  auto out = parseRangeLayout(output, top_deg, bottom_deg);
  if (!out) return makeError("--upsample-output: " + out.error().message);
  auto options = makeUpsampleOptions(method, *in, *out, model_path);
  if (!options) return makeError("--upsample: " + options.error().message);
  return std::optional<UpsampleOptions>(std::move(*options));
}

}  // namespace densemap::upsample
