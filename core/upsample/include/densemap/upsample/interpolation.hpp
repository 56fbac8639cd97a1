#pragma once

#include <string_view>

#include "densemap/geometry/error.hpp"
#include "densemap/upsample/range_image.hpp"

namespace densemap::upsample {

/// The baselines of Table 4.1: the 4 input pixels around a query, blended by bilinear weights,
/// or the nearest one. ILN (Eq. 4.3) blends the same 4 pixels with learned weights.
enum class Interpolation { kNearest, kBilinear };

[[nodiscard]] std::string_view interpolationName(Interpolation method);
[[nodiscard]] Expected<Interpolation> parseInterpolation(std::string_view name);

/// The 4 input pixels around a continuous (row, col) of `input`'s grid — rows clamped at the
/// field of view's edges, columns wrapping around — and their bilinear weights.
struct Neighbourhood {
  int row[4];
  int col[4];
  float range[4];   // 0: no return
  double weight[4];  // bilinear, summing to 1
  double d_row, d_col;  // the query's offset from the top-left neighbour, each in [0, 1]
};
[[nodiscard]] Neighbourhood neighbourhood(const RangeImage& input, double row, double col);

/// The range at a continuous (row, col) of `input`'s grid; 0 when no return can be given.
/// Missing returns are never blended in: bilinear renormalises over the neighbours that have
/// returns, nearest takes the nearest pixel with a return only if it is the nearest pixel.
[[nodiscard]] float interpolate(const RangeImage& input, double row, double col,
                                Interpolation method);

/// `input` resampled to `output`'s grid (same field of view frame), in parallel.
[[nodiscard]] RangeImage upsample(const RangeImage& input, const RangeLayout& output,
                                  Interpolation method);

}  // namespace densemap::upsample
