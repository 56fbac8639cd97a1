// Range images and the interpolation baselines (dissertation Sec. 4.2, Table 4.1).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>

#include "densemap/eval/point_set_metrics.hpp"
#include "densemap/upsample/interpolation.hpp"
#include "densemap/upsample/range_image.hpp"

namespace densemap::upsample {
namespace {

const RangeLayout kInput{.rows = 16, .cols = 256, .top_deg = 15.0, .bottom_deg = -15.0};

TEST(RangeLayout, RejectsBadGrids) {
  EXPECT_TRUE(kInput.validate());
  EXPECT_FALSE((RangeLayout{.rows = 1}).validate());
  EXPECT_FALSE((RangeLayout{.cols = 0}).validate());
  EXPECT_FALSE((RangeLayout{.top_deg = -20.0, .bottom_deg = -15.0}).validate());
  EXPECT_FALSE((RangeLayout{.top_deg = 95.0}).validate());
}

TEST(RangeLayout, FinerGridsShareTheFieldOfView) {
  const RangeLayout fine{.rows = 61, .cols = 1024};  // 4x: every 4th row is an input row
  for (const int r : {0, 4, 20, 60}) {
    const auto [row, col] = fine.toLayout(kInput, r, 8);
    EXPECT_NEAR(row, r / 4.0, 1e-12);
    EXPECT_NEAR(col, 2.0, 1e-12);
  }
}

TEST(RangeImage, ProjectionRoundTripsThroughPoints) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> range(0.5F, 80.0F);
  std::bernoulli_distribution has_return(0.8);
  RangeImage image(kInput);
  for (float& r : image.range) r = has_return(rng) ? range(rng) : 0.0F;
  ProjectionStats stats;
  const RangeImage back = project(backProject(image), kInput, &stats);
  EXPECT_EQ(stats.points, image.returns());
  EXPECT_EQ(stats.outside_fov, 0U);
  EXPECT_EQ(stats.collisions, 0U);
  ASSERT_EQ(back.range.size(), image.range.size());
  for (std::size_t i = 0; i < image.range.size(); ++i) {
    ASSERT_NEAR(back.range[i], image.range[i], 1e-4F * image.range[i]) << "pixel " << i;
  }
}

TEST(RangeImage, ProjectionKeepsTheNearerReturnAndCountsWhatItDrops) {
  const PointCloud points = {{10, 0, 0}, {5, 0, 0}, {0, 0, 3}, {std::nanf(""), 0, 0}};
  ProjectionStats stats;
  const RangeImage image = project(points, kInput, &stats);
  EXPECT_EQ(stats.points, 4U);
  EXPECT_EQ(stats.collisions, 1U);
  EXPECT_EQ(stats.outside_fov, 2U);                        // straight up, and NaN
  EXPECT_FLOAT_EQ(image.at(7, 0) + image.at(8, 0), 5.0F);  // 0 deg lies between rows 7 and 8
}

/// An image whose range is affine in (row, col) — a plane in range-image space — away from
/// the columns where azimuth wraps.
RangeImage affineImage(const RangeLayout& l) {
  RangeImage image(l);
  for (int r = 0; r < l.rows; ++r) {
    for (int c = 0; c < l.cols; ++c) image.at(r, c) = 5.0F + 0.3F * r + 0.01F * c;
  }
  return image;
}

TEST(Interpolation, BilinearIsExactOnAPlaneAndBothAreExactOnASphere) {
  const RangeImage input = affineImage(kInput);
  const RangeLayout output{.rows = 61, .cols = 1024};
  const RangeImage bilinear = upsample(input, output, Interpolation::kBilinear);
  for (int r = 0; r < output.rows; ++r) {
    for (int c = 0; c < output.cols - 4; ++c) {  // the last input column blends with column 0
      const auto [row, col] = output.toLayout(kInput, r, c);
      ASSERT_NEAR(bilinear.at(r, c), 5.0 + 0.3 * row + 0.01 * col, 1e-4) << r << "," << c;
    }
  }
  RangeImage sphere(kInput);
  std::fill(sphere.range.begin(), sphere.range.end(), 7.5F);
  for (const auto method : {Interpolation::kBilinear, Interpolation::kNearest}) {
    const RangeImage out = upsample(sphere, output, method);
    for (const float r : out.range) ASSERT_FLOAT_EQ(r, 7.5F);
  }
}

TEST(Interpolation, NearestPicksTheClosestPixel) {
  const RangeImage input = affineImage(kInput);
  EXPECT_FLOAT_EQ(interpolate(input, 2.3, 10.6, Interpolation::kNearest), input.at(2, 11));
  EXPECT_FLOAT_EQ(interpolate(input, 2.7, 10.4, Interpolation::kNearest), input.at(3, 10));
  // Columns wrap around the revolution; rows clamp at the field of view's edges.
  EXPECT_FLOAT_EQ(interpolate(input, 0.0, 255.7, Interpolation::kNearest), input.at(0, 0));
  EXPECT_FLOAT_EQ(interpolate(input, -0.4, 3.0, Interpolation::kNearest), input.at(0, 3));
}

TEST(Interpolation, MissingReturnsAreNeverBlendedIn) {
  RangeImage input(kInput);
  input.at(4, 10) = 10.0F;
  input.at(4, 11) = 20.0F;  // rows 5 are empty
  // Bilinear renormalises over the pixels with returns.
  EXPECT_NEAR(interpolate(input, 4.5, 10.5, Interpolation::kBilinear), 15.0, 1e-5);
  EXPECT_NEAR(interpolate(input, 4.9, 10.25, Interpolation::kBilinear), 12.5, 1e-5);
  // Nearest gives no return when the nearest pixel has none.
  EXPECT_EQ(interpolate(input, 4.9, 10.25, Interpolation::kNearest), 0.0F);
  // Nothing around: no return.
  EXPECT_EQ(interpolate(input, 9.5, 100.5, Interpolation::kBilinear), 0.0F);
}

TEST(Interpolation, NamesRoundTrip) {
  for (const auto m : {Interpolation::kBilinear, Interpolation::kNearest}) {
    EXPECT_EQ(*parseInterpolation(interpolationName(m)), m);
  }
  EXPECT_FALSE(parseInterpolation("bicubic"));
}

TEST(RangeImage, EveryNthRowIsASparserSensorInTheSameFrame) {
  const RangeLayout full{.rows = 64, .cols = 32, .top_deg = 45.0, .bottom_deg = -45.0};
  const RangeImage image = affineImage(full);
  const RangeImage sparse = keepEveryNthRow(image, 4);
  EXPECT_EQ(sparse.layout.rows, 16);
  EXPECT_DOUBLE_EQ(sparse.layout.top_deg, 45.0);
  EXPECT_NEAR(sparse.layout.bottom_deg, full.elevationDeg(60), 1e-12);
  for (int r = 0; r < 16; ++r) {
    EXPECT_NEAR(sparse.layout.elevationDeg(r), full.elevationDeg(4 * r), 1e-9);
    EXPECT_EQ(sparse.at(r, 5), image.at(4 * r, 5));
  }
  // Upsampled back, the kept rows come back exactly.
  const RangeImage back = upsample(sparse, full, Interpolation::kBilinear);
  for (int r = 0; r <= 60; r += 4) EXPECT_NEAR(back.at(r, 7), image.at(r, 7), 1e-4);
}

TEST(CompareRanges, MaeOverPixelsBothHaveAndCoverage) {
  RangeImage truth(kInput), predicted(kInput);
  truth.at(0, 0) = 10.0F;
  truth.at(0, 1) = 20.0F;
  truth.at(0, 2) = 30.0F;
  predicted.at(0, 0) = 11.0F;
  predicted.at(0, 1) = 17.0F;
  predicted.at(0, 3) = 5.0F;  // no truth there: not compared
  const auto e = compareRanges(predicted, truth);
  ASSERT_TRUE(e);
  EXPECT_DOUBLE_EQ(e->mae, 2.0);
  EXPECT_EQ(e->pixels, 2U);
  EXPECT_NEAR(e->coverage, 2.0 / 3.0, 1e-12);
  EXPECT_FALSE(compareRanges(RangeImage(RangeLayout{.rows = 4}), truth));
}

TEST(PointSetMetrics, VoxelIouPrecisionRecall) {
  // Truth: 4 voxels; prediction: 2 of them plus 2 others (one duplicated point).
  const PointCloud truth = {
      {0.05F, 0.05F, 0.05F}, {0.15F, 0.05F, 0.05F}, {0.25F, 0.05F, 0.05F}, {0.35F, 0.05F, 0.05F}};
  const PointCloud predicted = {{0.05F, 0.05F, 0.05F},
                                {0.06F, 0.04F, 0.05F},
                                {0.15F, 0.05F, 0.05F},
                                {1.05F, 0.05F, 0.05F},
                                {2.05F, 0.05F, 0.05F}};
  const auto m = eval::comparePointSets(predicted, truth, 0.1);
  EXPECT_EQ(m.predicted_voxels, 4U);
  EXPECT_EQ(m.true_voxels, 4U);
  EXPECT_EQ(m.common_voxels, 2U);
  EXPECT_NEAR(m.iou, 2.0 / 6.0, 1e-12);
  EXPECT_NEAR(m.precision, 0.5, 1e-12);
  EXPECT_NEAR(m.recall, 0.5, 1e-12);
  EXPECT_NEAR(m.f1, 0.5, 1e-12);
}

/// An uneven 8-beam table, pairs 1 and 2 deg apart (like BALM's OS0-64), top first.
std::vector<double> unevenBeams() { return {20.0, 19.0, 17.0, 16.0, 14.0, 13.0, 11.0, 10.0}; }

TEST(BeamTable, LayoutFollowsTheTableAndRejectsBadOnes) {
  const auto layout = withBeams(unevenBeams(), 64);
  ASSERT_TRUE(layout);
  EXPECT_EQ(layout->rows, 8);
  EXPECT_DOUBLE_EQ(layout->top_deg, 20.0);
  EXPECT_DOUBLE_EQ(layout->bottom_deg, 10.0);
  EXPECT_DOUBLE_EQ(layout->elevationDeg(2), 17.0);
  EXPECT_DOUBLE_EQ(layout->elevationDeg(1.5), 18.0);   // halfway in elevation
  EXPECT_DOUBLE_EQ(layout->elevationDeg(-1.0), 21.0);  // beyond the edges at their spacing
  for (const double e : {20.5, 19.7, 17.2, 13.9, 10.0, 9.0}) {
    EXPECT_NEAR(layout->elevationDeg(layout->pixelOf(e, 0.3).first), e, 1e-12) << e;
  }
  EXPECT_FALSE(withBeams({20.0, 20.0, 10.0}, 64));  // not strictly decreasing
  EXPECT_FALSE(withBeams({20.0}, 64));
  RangeLayout inconsistent = *layout;
  inconsistent.top_deg = 25.0;
  EXPECT_FALSE(inconsistent.validate());
  // Every n-th beam keeps its elevations; projection lands on the nearest beam and back.
  RangeImage image(*layout);
  for (std::size_t i = 0; i < image.range.size(); ++i) image.range[i] = 5.0F + 0.01F * i;
  ProjectionStats stats;
  const RangeImage back = project(backProject(image), *layout, &stats);
  EXPECT_EQ(stats.collisions, 0U);
  EXPECT_EQ(stats.outside_fov, 0U);
  for (std::size_t i = 0; i < image.range.size(); ++i) {
    ASSERT_NEAR(back.range[i], image.range[i], 1e-4F) << "pixel " << i;
  }
  const RangeImage sparse = keepEveryNthRow(image, 2);
  EXPECT_EQ(sparse.layout.beams_deg, (std::vector<double>{20.0, 17.0, 14.0, 11.0}));
  EXPECT_TRUE(sparse.layout.validate());
  // Beam 1 (19 deg) lies a third of the way from kept beam 0 (20) to kept beam 1 (17).
  EXPECT_NEAR(layout->toLayout(sparse.layout, 1, 0).first, 1.0 / 3.0, 1e-12);
}

TEST(BeamTable, FileRoundTripsAndBadLinesAreNamed) {
  const auto path = std::filesystem::temp_directory_path() / "densemap_beams_test.txt";
  {
    std::ofstream out(path);
    out << formatBeamTable(unevenBeams(), "test table\nsecond line");
  }
  const auto read = readBeamTable(path.string());
  ASSERT_TRUE(read);
  EXPECT_EQ(*read, unevenBeams());
  {
    std::ofstream out(path);
    out << "# comment\n20.0\n\n19.5 # trailing comment\n18 17\n";
  }
  const auto bad = readBeamTable(path.string());
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find(":5:"), std::string::npos) << bad.error().message;
  {
    std::ofstream out(path);
    out << "95\n";
  }
  EXPECT_FALSE(readBeamTable(path.string()));
  std::filesystem::remove(path);
  EXPECT_FALSE(readBeamTable(path.string()));
}

TEST(BeamTable, EstimatedFromScansOfAnUnevenSensor) {
  // Returns of the uneven sensor at 3..30 m with 0.03 deg of elevation noise, and near returns
  // (under the estimate's 3 m) far off their beams.
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> range(3.5, 30.0), azimuth(-3.1, 3.1);
  std::normal_distribution<double> noise(0.0, 0.03);
  std::vector<PointCloud> scans(2);
  for (PointCloud& scan : scans) {
    for (const double beam : unevenBeams()) {
      for (int i = 0; i < 400; ++i) {
        const double e = (beam + noise(rng)) * std::numbers::pi / 180.0, a = azimuth(rng);
        const double r = range(rng);
        scan.emplace_back(static_cast<float>(r * std::cos(e) * std::cos(a)),
                          static_cast<float>(r * std::cos(e) * std::sin(a)),
                          static_cast<float>(r * std::sin(e)));
        scan.emplace_back(0.5F, 0.0F, static_cast<float>(i % 7) * 0.1F);  // near, ignored
      }
    }
  }
  const auto beams = estimateBeams(scans, 8);
  ASSERT_TRUE(beams) << beams.error().message;
  ASSERT_EQ(beams->size(), 8U);
  for (std::size_t b = 0; b < 8; ++b) EXPECT_NEAR((*beams)[b], unevenBeams()[b], 0.01);
  EXPECT_FALSE(estimateBeams({PointCloud{}}, 8));  // too few returns
}

}  // namespace
}  // namespace densemap::upsample
