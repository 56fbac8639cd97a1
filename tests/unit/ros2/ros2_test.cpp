// ROS 2 wire content without DDS: PointCloud2 layouts and malformed clouds, the TF buffer's
// chaining and interpolation, and the map topics' incremental state against a whole-map
// reference.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <random>

#include "densemap/map/grid_map.hpp"
#include "densemap/query/map_view.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/ros2/map_topics.hpp"
#include "densemap/ros2/point_cloud2.hpp"
#include "densemap/ros2/tf_buffer.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap::ros2 {
namespace {

constexpr std::uint8_t kF32 = 7, kF64 = 8, kU16 = 4, kU8 = 2;

/// A cloud builder: fields at given offsets, points written with memcpy.
struct CloudBytes {
  std::vector<PointFieldView> fields;
  std::vector<std::uint8_t> data;
  PointCloud2View view() const {
    PointCloud2View v;
    v.fields = fields;
    v.data = data;
    return v;
  }
};

template <class T>
void put(std::vector<std::uint8_t>& data, std::size_t at, T value, bool big_endian = false) {
  std::uint8_t raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  if (big_endian) std::reverse(raw, raw + sizeof(T));
  std::memcpy(data.data() + at, raw, sizeof(T));
}

const std::vector<std::array<float, 3>> kPoints = {
    {1.5F, -2.25F, 0.125F}, {10.0F, 0.0F, -1.0F}, {-3.0F, 4.0F, 5.5F}, {0.1F, 0.2F, 0.3F}};

TEST(PointCloud2, PackedXyzFloat32) {
  CloudBytes c;
  c.fields = {{"x", 0, kF32, 1}, {"y", 4, kF32, 1}, {"z", 8, kF32, 1}};
  c.data.resize(12 * kPoints.size());
  for (std::size_t i = 0; i < kPoints.size(); ++i) {
    for (int a = 0; a < 3; ++a) put(c.data, 12 * i + 4 * a, kPoints[i][a]);
  }
  PointCloud2View v = c.view();
  v.height = 1;
  v.width = 4;
  v.point_step = 12;
  v.row_step = 48;
  auto d = decodePointCloud2(v, 100);
  ASSERT_TRUE(d);
  ASSERT_EQ(d->xyz.size(), 12U);
  for (std::size_t i = 0; i < kPoints.size(); ++i) {
    for (int a = 0; a < 3; ++a) EXPECT_EQ(d->xyz[3 * i + a], kPoints[i][a]);
  }
  EXPECT_TRUE(d->intensity.empty());
}

/// Velodyne-like layout (x y z pad intensity ring), organized 2 x 2 with row padding, z first
/// in the field list, NaN points, in every combination of endianness and coordinate type.
TEST(PointCloud2, PaddedOrganizedLayoutsInBothByteOrdersAndBothFloatTypes) {
  for (const bool big : {false, true}) {
    for (const bool f64 : {false, true}) {
      SCOPED_TRACE(std::string(big ? "big" : "little") + (f64 ? " float64" : " float32"));
      const std::uint32_t size = f64 ? 8 : 4;
      CloudBytes c;
      c.fields = {{"z", 2 * size, f64 ? kF64 : kF32, 1},
                  {"ring", 3 * size + 8, kU16, 1},
                  {"y", size, f64 ? kF64 : kF32, 1},
                  {"intensity", 3 * size + 4, kF32, 1},
                  {"x", 0, f64 ? kF64 : kF32, 1}};
      const std::uint32_t point_step = 3 * size + 16, row_step = 2 * point_step + 7;
      c.data.assign(2 * row_step, 0xAB);
      for (std::size_t i = 0; i < 4; ++i) {
        const std::size_t at = (i / 2) * row_step + (i % 2) * point_step;
        std::array<float, 3> p = kPoints[i];
        if (i == 2) p[1] = std::numeric_limits<float>::quiet_NaN();  // a dropped return
        for (int a = 0; a < 3; ++a) {
          if (f64) {
            put(c.data, at + a * size, static_cast<double>(p[a]), big);
          } else {
            put(c.data, at + a * size, p[a], big);
          }
        }
        put(c.data, at + 3 * size + 4, 10.0F * i, big);
        put(c.data, at + 3 * size + 8, std::uint16_t(7), big);
      }
      PointCloud2View v = c.view();
      v.height = 2;
      v.width = 2;
      v.point_step = point_step;
      v.row_step = row_step;
      v.is_bigendian = big;
      v.is_dense = false;
      auto d = decodePointCloud2(v, 100);
      ASSERT_TRUE(d) << cloudRejectName(d.error());
      EXPECT_EQ(d->non_finite, 1U);
      ASSERT_EQ(d->xyz.size(), 9U);
      ASSERT_EQ(d->intensity.size(), 3U);
      std::size_t k = 0;
      for (std::size_t i : {0U, 1U, 3U}) {
        for (int a = 0; a < 3; ++a) EXPECT_EQ(d->xyz[3 * k + a], kPoints[i][a]);
        EXPECT_EQ(d->intensity[k], 10.0F * i);
        ++k;
      }
    }
  }
}

TEST(PointCloud2, MalformedCloudsAreRejectedWithTheirReason) {
  CloudBytes c;
  c.fields = {{"x", 0, kF32, 1}, {"y", 4, kF32, 1}, {"z", 8, kF32, 1}};
  c.data.assign(120, 0);
  PointCloud2View good = c.view();
  good.height = 1;
  good.width = 10;
  good.point_step = 12;
  good.row_step = 120;
  ASSERT_TRUE(decodePointCloud2(good, 100));
  auto expect = [](PointCloud2View v, CloudReject reason) {
    auto d = decodePointCloud2(v, 100);
    ASSERT_FALSE(d);
    EXPECT_EQ(d.error(), reason) << cloudRejectName(d.error());
  };
  PointCloud2View v = good;
  v.point_step = 8;  // z at offset 8 ends past the point
  v.row_step = 80;
  expect(v, CloudReject::kFieldPastPoint);
  v = good;
  v.data = std::span<const std::uint8_t>(c.data).first(119);  // one byte short
  expect(v, CloudReject::kDataTooShort);
  v = good;
  v.row_step = 100;
  expect(v, CloudReject::kRowTooShort);
  v = good;
  v.width = 0xFFFFFFFFU;
  v.height = 0xFFFFFFFFU;  // 2^64 - ... points: neither overflow nor a read
  expect(v, CloudReject::kTooManyPoints);
  v = good;
  v.width = 0;
  expect(v, CloudReject::kEmpty);
  std::vector<PointFieldView> no_z = {{"x", 0, kF32, 1}, {"y", 4, kF32, 1}};
  v = good;
  v.fields = no_z;
  expect(v, CloudReject::kMissingXyz);
  std::vector<PointFieldView> int_x = {{"x", 0, kU16, 1}, {"y", 4, kF32, 1}, {"z", 8, kF32, 1}};
  v = good;
  v.fields = int_x;
  expect(v, CloudReject::kUnsupportedXyz);
  std::vector<PointFieldView> far_x = {
      {"x", 0xFFFFFFF0U, kF32, 1}, {"y", 4, kF32, 1}, {"z", 8, kF32, 1}};
  v = good;
  v.fields = far_x;
  expect(v, CloudReject::kFieldPastPoint);
  std::vector<PointFieldView> far_intensity = {
      {"x", 0, kF32, 1}, {"y", 4, kF32, 1}, {"z", 8, kF32, 1}, {"intensity", 11, kU8, 2}};
  v = good;
  v.fields = far_intensity;  // uint8 at 11 fits a 12-byte point
  EXPECT_TRUE(decodePointCloud2(v, 100));
  far_intensity[3].datatype = kF32;
  v.fields = far_intensity;
  expect(v, CloudReject::kFieldPastPoint);
}

TEST(PointCloud2, RandomLayoutsNeverReadPastTheData) {
  std::mt19937 rng(5);
  std::size_t accepted = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    auto r = [&](std::uint32_t n) { return static_cast<std::uint32_t>(rng() % n); };
    std::vector<PointFieldView> fields;
    const char* names[] = {"x", "y", "z", "intensity", "other"};
    for (const char* name : names) {
      if (r(12) == 0) continue;  // now and then a field is missing
      const bool axis = name[1] == '\0';
      const auto type = static_cast<std::uint8_t>(axis && r(5) != 0 ? 7 + r(2) : r(10));
      fields.push_back({name, r(28), type, r(8) == 0 ? 0U : 1U});
    }
    PointCloud2View v;
    v.fields = fields;
    v.height = r(4);
    v.width = r(12);
    v.point_step = r(48);
    v.row_step = r(3) == 0 ? r(300) : v.width * v.point_step + r(8);
    const long exact = static_cast<long>(std::size_t{v.row_step} * v.height);
    std::vector<std::uint8_t> data(
        r(3) == 0 ? r(400)
                  : static_cast<std::size_t>(std::max(0L, exact + static_cast<long>(r(16)) - 8)));
    v.data = data;
    v.is_bigendian = r(2) == 1;
    auto d = decodePointCloud2(v, 1000);
    if (d) {
      ++accepted;
      EXPECT_LE(std::uint64_t{v.row_step} * v.height, data.size());
      EXPECT_EQ(d->xyz.size() / 3 + d->non_finite, std::size_t{v.width} * v.height);
    }
  }
  EXPECT_GT(accepted, 10U);  // the generator does produce valid clouds too
}

TfSample sample(std::int64_t stamp, Eigen::Vector3d t, double yaw) {
  return {stamp, t, Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()))};
}

TEST(TfBuffer, ChainsStaticAndMovingLinksAndInterpolates) {
  TfBuffer tf;
  ASSERT_TRUE(tf.set("map", "odom", sample(0, {1, 0, 0}, 0), true));
  ASSERT_TRUE(tf.set("odom", "base_link", sample(1'000'000'000, {0, 0, 0}, 0), false));
  ASSERT_TRUE(tf.set("odom", "base_link", sample(2'000'000'000, {2, 4, 0}, M_PI / 2), false));
  ASSERT_TRUE(tf.set("/base_link", "lidar", sample(0, {0, 0, 1}, 0), true));
  auto T = tf.lookup("map", "lidar", 1'500'000'000);
  ASSERT_TRUE(T);
  // Halfway: odom->base_link at (1, 2, 0) turned 45 deg; lidar 1 m above; map 1 m before odom.
  EXPECT_NEAR((T->translation() - Eigen::Vector3d(2, 2, 1)).norm(), 0.0, 1e-12);
  const Eigen::Vector3d x = T->linear() * Eigen::Vector3d::UnitX();
  EXPECT_NEAR(x.x(), std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(x.y(), std::sqrt(0.5), 1e-12);
  // Exactly at a sample: that sample.
  auto at = tf.lookup("map", "lidar", 2'000'000'000);
  ASSERT_TRUE(at);
  EXPECT_NEAR((at->translation() - Eigen::Vector3d(3, 4, 1)).norm(), 0.0, 1e-12);
  // The inverse direction, and stamp 0 = the latest common time.
  auto back = tf.lookup("lidar", "map", 1'500'000'000);
  ASSERT_TRUE(back);
  EXPECT_NEAR(((*back) * (*T)).matrix().isIdentity(1e-12), 1.0, 0.0);
  auto latest = tf.lookup("map", "lidar", 0);
  ASSERT_TRUE(latest);
  EXPECT_TRUE(latest->isApprox(*at, 1e-12));
  // Not yet, too old, unknown, unconnected.
  EXPECT_EQ(tf.lookup("map", "lidar", 2'000'000'001).error(), TfFailure::kNotYet);
  EXPECT_EQ(tf.lookup("map", "lidar", 999'999'999).error(), TfFailure::kTooOld);
  EXPECT_EQ(tf.lookup("map", "camera", 1'500'000'000).error(), TfFailure::kUnknownFrame);
  ASSERT_TRUE(tf.set("world", "other", sample(0, {0, 0, 0}, 0), true));
  EXPECT_EQ(tf.lookup("map", "other", 0).error(), TfFailure::kNoPath);
}

TEST(TfBuffer, RejectsBadSamplesAndForgetsOldOnes) {
  TfBuffer tf(1'000'000'000);
  TfSample bad = sample(0, {0, 0, 0}, 0);
  bad.q = Eigen::Quaterniond(0, 0, 0, 0);
  EXPECT_FALSE(tf.set("a", "b", bad, false));
  bad.q = Eigen::Quaterniond(2, 0, 0, 0);
  EXPECT_FALSE(tf.set("a", "b", bad, false));
  bad = sample(0, {std::nan(""), 0, 0}, 0);
  EXPECT_FALSE(tf.set("a", "b", bad, false));
  EXPECT_FALSE(tf.set("a", "a", sample(0, {0, 0, 0}, 0), false));
  EXPECT_FALSE(tf.set("", "b", sample(0, {0, 0, 0}, 0), false));
  ASSERT_TRUE(tf.set("a", "b", sample(0, {0, 0, 0}, 0), false));
  EXPECT_FALSE(tf.set("b", "a", sample(0, {0, 0, 0}, 0), false));  // a cycle
  for (int s = 1; s <= 40; ++s) {
    ASSERT_TRUE(tf.set("a", "b", sample(s * 100'000'000LL, {0.1 * s, 0, 0}, 0), false));
  }
  // 4 s of samples with a 1 s cache: the first seconds are gone.
  EXPECT_EQ(tf.lookup("a", "b", 500'000'000).error(), TfFailure::kTooOld);
  EXPECT_TRUE(tf.lookup("a", "b", 3'500'000'000));
}

/// A map after `scans` adversarial scans.
std::unique_ptr<GridMap> makeMap(int scans, int seed) {
  auto map = std::make_unique<GridMap>(0.2, SensorModel{});
  Integrator integrator({.max_range_m = 6.0});
  for (int s = 0; s < scans; ++s) {
    const Point3f o(0.5F * s, 0, 0.2F);
    integrator.integrate(*map, test::adversarialScan(0.2, o, 1500, 6.0, seed + s), o);
  }
  return map;
}

std::vector<std::uint64_t> allBlocks(const MapView& a, const MapView& b) {
  std::vector<std::uint64_t> blocks;
  for (const MapView* v : {&a, &b}) {
    v->forEachBlock([&](std::uint64_t key, const VoxelBlock&) { blocks.push_back(key); });
  }
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  return blocks;
}

void expectStateEquals(const MapTopicsState& state, const MapView& view, double lo, double hi) {
  // The OctoMap stream read back by OctoMap: every known cell, occupied as densemap says.
  std::istringstream in(state.binaryData());
  octomap::OcTree tree(view.grid().resolution());
  ASSERT_TRUE(tree.readBinaryData(in));
  std::size_t cells = 0;
  view.forEachKnown([&](const VoxelKey& k, float v) {
    ++cells;
    const octomap::OcTreeNode* n = tree.search(octomap::OcTreeKey(k.x, k.y, k.z));
    ASSERT_NE(n, nullptr);
    EXPECT_EQ(tree.isNodeOccupied(n), SensorModel::isOccupied(v));
  });
  tree.expand();
  EXPECT_EQ(tree.getNumLeafNodes(), cells);
  EXPECT_EQ(state.cells(), cells);
  const GridImage got = state.projectedGrid(), want = MapTopicsState::project(view, lo, hi);
  EXPECT_EQ(got.width, want.width);
  EXPECT_EQ(got.height, want.height);
  EXPECT_EQ(got.origin_x, want.origin_x);
  EXPECT_EQ(got.origin_y, want.origin_y);
  EXPECT_EQ(got.data, want.data);
  std::size_t occupied = 0;
  view.forEachKnown([&](const VoxelKey&, float v) { occupied += SensorModel::isOccupied(v); });
  EXPECT_EQ(state.occupiedCenters().size(), occupied);
}

TEST(MapTopicsState, IncrementalUpdatesEqualTheWholeMapReference) {
  constexpr double kLo = -0.3, kHi = 1.0;
  auto a = makeMap(2, 1);
  auto b = makeMap(3, 1);  // grows
  b->erase(VoxelKey{32768, 32768, 32769});
  auto c = makeMap(1, 9);  // a different map: cells appear and disappear
  const auto va = MapView::fromMap(*a, 1), vb = MapView::fromMap(*b, 2),
             vc = MapView::fromMap(*c, 3);
  MapTopicsState state(0.2, kLo, kHi);
  state.update(nullptr, *va, {});
  expectStateEquals(state, *va, kLo, kHi);
  state.update(va.get(), *vb, allBlocks(*va, *vb));
  expectStateEquals(state, *vb, kLo, kHi);
  state.update(vb.get(), *vc, allBlocks(*vb, *vc));
  expectStateEquals(state, *vc, kLo, kHi);
  const GridImage grid = state.projectedGrid();
  EXPECT_GT(std::count(grid.data.begin(), grid.data.end(), 100), 10);
  EXPECT_GT(std::count(grid.data.begin(), grid.data.end(), 0), 10);
}

// /octomap_binary is pruned as octomap_server's is (eight equal children
// become their parent), still every cell as densemap has it, and a pruned region updated
// later is expanded again cell for cell.
TEST(MapTopicsState, TheOctomapIsPrunedAndStillEveryCell) {
  GridMap map(0.2, SensorModel{});
  // A free room 3.2 m a side (16^3 cells: aligned octants prune) with an occupied wall.
  const std::uint16_t o = 32768;
  for (std::uint16_t x = o; x < o + 16; ++x) {
    for (std::uint16_t y = o; y < o + 16; ++y) {
      for (std::uint16_t z = o; z < o + 16; ++z) {
        map.setLogOdds(VoxelKey{x, y, z}, x == o + 15 ? 2.0F : -2.0F);
      }
    }
  }
  const auto v1 = MapView::fromMap(map, 1);
  MapTopicsState state(0.2, -1.0, 4.0);
  state.update(nullptr, *v1, {});
  expectStateEquals(state, *v1, -1.0, 4.0);
  std::istringstream in(state.binaryData());
  octomap::OcTree tree(0.2);
  ASSERT_TRUE(tree.readBinaryData(in));
  // 4,096 cells: pruned to a few hundred nodes (unpruned, the leaves alone are 4,096).
  EXPECT_LT(tree.size(), 700U);
  EXPECT_LT(state.tree().size(), 700U);
  // One free cell in the middle of a pruned octant becomes occupied: the octant expands.
  map.setLogOdds(VoxelKey{o + 3, o + 3, o + 3}, 1.5F);
  const auto v2 = MapView::fromMap(map, 2);
  state.update(v1.get(), *v2, allBlocks(*v1, *v2));
  expectStateEquals(state, *v2, -1.0, 4.0);
}

}  // namespace
}  // namespace densemap::ros2
