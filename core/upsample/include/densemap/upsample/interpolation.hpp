#pragma once

#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "densemap/geometry/error.hpp"
#include "densemap/upsample/range_image.hpp"

namespace densemap::upsample {

class IlnModel;

/// The baselines of Table 4.1: the 4 input pixels around a query, blended by bilinear weights,
/// or the nearest one; and ILN (Eq. 4.3), which blends the same 4 pixels with learned weights
/// (an IlnModel, iln.hpp).
enum class Interpolation { kNearest, kBilinear, kIln };

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

  /// Whether neighbour t may be blended: it has a return and the query is not on a pixel line
  /// that leaves it out (zero bilinear weight).
  [[nodiscard]] bool usable(int t) const { return range[t] > 0.0F && weight[t] > 0.0; }
};
[[nodiscard]] Neighbourhood neighbourhood(const RangeImage& input, double row, double col);

/// The range at a continuous (row, col) of `input`'s grid; 0 when no return can be given.
/// Missing returns are never blended in: bilinear renormalises over the neighbours that have
/// returns, nearest takes the nearest pixel with a return only if it is the nearest pixel.
/// kNearest or kBilinear (kIln needs an encoded input: IlnModel::predict).
[[nodiscard]] float interpolate(const RangeImage& input, double row, double col,
                                Interpolation method);

/// A densification step for a stream of scans: sensor-frame points projected onto the sensor's
/// grid `input`, upsampled to `output` (same field of view), back-projected.
struct UpsampleOptions {
  RangeLayout input{.rows = 16, .cols = 1024};
  RangeLayout output{.rows = 64, .cols = 1024};
  Interpolation method = Interpolation::kBilinear;
  /// The model for Interpolation::kIln.
  std::shared_ptr<const IlnModel> iln;

  /// Errors for bad grids, an output in another field of view, or kIln without a model.
  [[nodiscard]] Expected<void> validate() const;
};

/// Options for `method` ("nearest", "bilinear" or "iln") between two grids; for "iln" the
/// weights file `model_path` is loaded. Errors name what is wrong (method, grids, model file).
[[nodiscard]] Expected<UpsampleOptions> makeUpsampleOptions(std::string_view method,
                                                            const RangeLayout& input,
                                                            const RangeLayout& output,
                                                            const std::string& model_path);

/// The command line's densify flags as options (densemap replay, densemap-eval): `method`
/// (--upsample; empty: none), the grids ROWSxCOLS (--upsample-input, --upsample-output) in the
/// field of view [bottom_deg, top_deg] (--fov-top, --fov-bottom) and --upsample-model. Errors
/// name the flag.
[[nodiscard]] Expected<std::optional<UpsampleOptions>> upsampleFromFlags(
    const std::string& method, const std::string& input, const std::string& output,
    double top_deg, double bottom_deg, const std::string& model_path);

/// Densifies one scan's sensor-frame points (UpsampleOptions); `stats` describes the projection.
[[nodiscard]] PointCloud upsamplePoints(const PointCloud& points_sensor,
                                        const UpsampleOptions& options,
                                        ProjectionStats* stats = nullptr);

/// `input` resampled to `output`'s grid (same field of view frame), in parallel. kIln needs
/// `iln` (a missing model is a bug and aborts).
[[nodiscard]] RangeImage upsample(const RangeImage& input, const RangeLayout& output,
                                  Interpolation method, const IlnModel* iln = nullptr);

}  // namespace densemap::upsample
