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

/// A densification step for a stream of scans: sensor-frame points projected onto the sensor's
/// grid `input`, upsampled to `output` (same field of view), back-projected.
struct UpsampleOptions {
  RangeLayout input{.rows = 16, .cols = 1024};
  RangeLayout output{.rows = 64, .cols = 1024};
  Interpolation method = Interpolation::kBilinear;

  /// Errors for bad grids or an output in another field of view.
  [[nodiscard]] Expected<void> validate() const;
};

/// Densifies one scan's sensor-frame points (UpsampleOptions); `stats` describes the projection.
[[nodiscard]] PointCloud upsamplePoints(const PointCloud& points_sensor,
                                        const UpsampleOptions& options,
                                        ProjectionStats* stats = nullptr);

/// `input` resampled to `output`'s grid (same field of view frame), in parallel.
[[nodiscard]] RangeImage upsample(const RangeImage& input, const RangeLayout& output,
                                  Interpolation method);

}  // namespace densemap::upsample
