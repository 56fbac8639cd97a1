#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "densemap/geometry/error.hpp"
#include "densemap/geometry/point_cloud.hpp"

namespace densemap::upsample {

/// A spinning LiDAR's range-image grid (dissertation Sec. 4.2): `rows` beams spread evenly from
/// `top_deg` (row 0) down to `bottom_deg` (the last row), or at the elevations of a beam table
/// (`beams_deg`, a real sensor's uneven beams), and `cols` azimuth steps per revolution, column
/// c looking at azimuth 2 pi c / cols (as densemap-sim's sensors do).
/// Any rows x cols inside the same field of view is a valid query grid: the image coordinates
/// of a direction are continuous, so layouts of different resolutions share one frame. With a
/// beam table, a fractional row lies between its two beams in proportion to elevation (and
/// beyond the first and last beams at their neighbours' spacing).
struct RangeLayout {
  int rows = 16;
  int cols = 1024;
  double top_deg = 15.0;
  double bottom_deg = -15.0;
  /// Empty: evenly spread beams. Otherwise `rows` strictly decreasing elevations, deg, whose
  /// first and last equal top_deg and bottom_deg (withBeams sets all four).
  std::vector<double> beams_deg{};

  [[nodiscard]] Expected<void> validate() const;
  /// Elevation of row r (may be fractional), degrees.
  [[nodiscard]] double elevationDeg(double row) const;
  /// Azimuth of column c (may be fractional), radians.
  [[nodiscard]] double azimuth(double col) const;
  /// The continuous (row, col) of a direction in this layout; col in [0, cols).
  [[nodiscard]] std::pair<double, double> pixelOf(double elevation_deg, double azimuth) const;
  /// The same direction's (row, col) in `other`'s grid, from this layout's pixel (row, col).
  [[nodiscard]] std::pair<double, double> toLayout(const RangeLayout& other, double row,
                                                   double col) const;
};

/// "ROWSxCOLS" (e.g. "64x1024") in the field of view [bottom_deg, top_deg], validated.
[[nodiscard]] Expected<RangeLayout> parseRangeLayout(const std::string& text, double top_deg,
                                                     double bottom_deg);

/// A layout of `cols` columns with the beams of a table (elevations in degrees, strictly
/// decreasing, 2 to 4096 of them), validated.
[[nodiscard]] Expected<RangeLayout> withBeams(std::vector<double> beams_deg, int cols);

/// A beam table file: one elevation (deg) per line, top beam first; blank lines and lines from
/// '#' are ignored. Errors name the file and line.
[[nodiscard]] Expected<std::vector<double>> readBeamTable(const std::string& path);
/// The table as readBeamTable reads it, with `comment` (may hold several lines) on top.
[[nodiscard]] std::string formatBeamTable(const std::vector<double>& beams_deg,
                                          const std::string& comment);

/// A real sensor's beam table estimated from its sensor-frame scans: the elevations of the
/// returns farther than `min_range_m` (a sensor's origin offset bends near returns) grouped
/// into `rows` beams by 1-D k-means (started evenly spread between the extreme elevations),
/// each beam's elevation the mean of its group. Errors when there are fewer returns than 100
/// per beam or they do not separate into `rows` beams.
[[nodiscard]] Expected<std::vector<double>> estimateBeams(const std::vector<PointCloud>& scans,
                                                          int rows, double min_range_m = 3.0);

/// Ranges in metres, row-major; 0 marks a pixel without a return.
struct RangeImage {
  RangeLayout layout;
  std::vector<float> range;

  explicit RangeImage(const RangeLayout& l = {})
      : layout(l), range(static_cast<std::size_t>(l.rows) * l.cols, 0.0F) {}
  [[nodiscard]] float at(int row, int col) const {
    return range[static_cast<std::size_t>(row) * layout.cols + col];
  }
  float& at(int row, int col) { return range[static_cast<std::size_t>(row) * layout.cols + col]; }
  [[nodiscard]] std::size_t returns() const;
};

struct ProjectionStats {
  std::size_t points = 0;
  std::size_t outside_fov = 0;  // dropped: elevation beyond the layout's rows
  std::size_t collisions = 0;   // another point of the same pixel was kept (the nearer one)
};

/// Projects sensor-frame points onto the nearest pixel of `layout`, keeping the nearest return
/// per pixel. Non-finite points and points at the origin are skipped as outside.
[[nodiscard]] RangeImage project(const PointCloud& points_sensor, const RangeLayout& layout,
                                 ProjectionStats* stats = nullptr);

/// Mean absolute range error of `predicted` against `truth` (same layout) over the pixels where
/// both have a return; `coverage` is the share of truth's returns that `predicted` has.
struct RangeError {
  double mae = 0.0;
  double coverage = 0.0;
  std::size_t pixels = 0;  // compared
};
[[nodiscard]] Expected<RangeError> compareRanges(const RangeImage& predicted,
                                                 const RangeImage& truth);

/// Rows 0, n, 2n, ... of `image` as an image of their own (the same field of view frame, and
/// the same beams when the layout has a table): a sensor with every n-th beam, as for the
/// real-data test of Table 4.1's kind.
[[nodiscard]] RangeImage keepEveryNthRow(const RangeImage& image, int n);

/// The points of an image's returns, at their pixels' exact directions (sensor frame).
[[nodiscard]] PointCloud backProject(const RangeImage& image);

}  // namespace densemap::upsample
