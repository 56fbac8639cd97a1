// The paper-like benchmark scenes and the dense-oracle labels (the oracle protocol).
#include <gtest/gtest.h>

#include <fstream>
#include <set>

#include "densemap/io/scan_source.hpp"
#include "densemap/sim/oracle_labels.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/sim/trajectory.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap {
namespace {

TEST(BenchmarkScenes, AreTenBySevenByTwoWithFourFreeStations) {
  for (const char* name : {"structured", "unstructured"}) {
    auto scene = makeScene(name, 3);
    ASSERT_TRUE(scene) << name;
    EXPECT_TRUE(scene->stations);
    ASSERT_EQ(scene->waypoints.size(), 4U);
    const Eigen::AlignedBox3d bounds = scene->scene->bounds();
    EXPECT_NEAR(bounds.sizes().x(), 10.4, 1e-9);
    EXPECT_NEAR(bounds.sizes().y(), 7.4, 1e-9);
    for (const Eigen::Vector3d& s : scene->waypoints) {
      EXPECT_TRUE(bounds.contains(s)) << name;
      // The sensor stands in free space and sees something within 8 m in most directions.
      EXPECT_FALSE(scene->scene->overlapsBox(s.array() - 0.1, s.array() + 0.1)) << name;
      int hits = 0;
      for (int i = 0; i < 36; ++i) {
        const double a = i * 10.0 * M_PI / 180.0;
        hits += scene->scene->castRay(s, Eigen::Vector3d(std::cos(a), std::sin(a), -0.3).normalized(),
                                      8.0)
                    ? 1
                    : 0;
      }
      EXPECT_EQ(hits, 36) << name << ": the floor is always within reach";
    }
  }
}

TEST(PosesAtStations, ShareTheScansOutAndTurnEachOne) {
  const std::vector<Eigen::Vector3d> stations = {{0, 0, 1}, {1, 0, 1}, {2, 0, 1}, {3, 0, 1}};
  const auto poses = posesAtStations(stations, 14);
  ASSERT_EQ(poses.size(), 14U);
  // 4 + 4 + 3 + 3, in station order.
  EXPECT_TRUE(poses[3].translation().isApprox(stations[0]));
  EXPECT_TRUE(poses[4].translation().isApprox(stations[1]));
  EXPECT_TRUE(poses[13].translation().isApprox(stations[3]));
  EXPECT_FALSE(poses[0].linear().isApprox(poses[1].linear()));
}

TEST(DenseLidar, InterpolatesBeamsAndMultipliesColumns) {
  auto base = lidarPreset("vlp16");
  ASSERT_TRUE(base);
  base->noise_std_m = 0.05;
  const LidarModel dense = denseLidar(*base, 4);
  EXPECT_EQ(dense.beams(), (base->beams() - 1) * 4 + 1);
  EXPECT_EQ(dense.columns, base->columns * 4);
  EXPECT_EQ(dense.noise_std_m, 0.0);
  for (int b = 0; b < base->beams(); ++b) {
    EXPECT_EQ(dense.elevations_deg[static_cast<std::size_t>(4 * b)], base->elevations_deg[b]);
  }
}

TEST(OracleLabels, OccupiedWhereRaysEndFreeWhereTheyPassAndRoundTrip) {
  OracleLabeller oracle(0.1);
  const Point3f origin(0.05F, 0.05F, 0.05F);
  // Two rays along +x ending at 1.05 and at 0.55: the shorter one's end cell is crossed by the
  // longer one but stays occupied.
  oracle.add({Point3f(1.05F, 0.05F, 0.05F), Point3f(0.55F, 0.05F, 0.05F)}, origin);
  const auto labels = oracle.labels();
  std::set<std::pair<int, bool>> cells;  // (x index relative to the origin's, occupied)
  const VoxelKey o = *oracle.grid().pointToKey(origin);
  for (const LabelledVoxel& v : labels) {
    EXPECT_EQ(v.key.y, o.y);
    EXPECT_EQ(v.key.z, o.z);
    cells.insert({v.key.x - o.x, v.occupied});
  }
  std::set<std::pair<int, bool>> expected;
  for (int i = 0; i < 10; ++i) expected.insert({i, i == 5});
  expected.insert({10, true});
  EXPECT_EQ(cells, expected);

  test::TempDir dir;
  const auto path = oracleLabelsPath(dir.path(), 0.1);
  EXPECT_EQ(path.filename(), "oracle_0.1.bt");
  ASSERT_TRUE(oracle.write(path));
  const auto back = readOracleLabels(path, 0.1);
  ASSERT_TRUE(back) << back.error().message;
  std::set<std::pair<int, bool>> read;
  for (const LabelledVoxel& v : *back) read.insert({v.key.x - o.x, v.occupied});
  EXPECT_EQ(read, expected);
}

TEST(OracleLabels, MissingBrokenOrMismatchedFilesGiveClearErrors) {
  test::TempDir dir;
  const auto missing = readOracleLabels(dir.path() / "oracle_0.1.bt", 0.1);
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("--oracle-factor"), std::string::npos);
  std::ofstream(dir.path() / "broken.bt") << "# Octomap OcTree binary file\nnonsense";
  EXPECT_FALSE(readOracleLabels(dir.path() / "broken.bt", 0.1));
  OracleLabeller oracle(0.2);
  oracle.add({Point3f(1, 0, 0)}, Point3f(0, 0, 0));
  ASSERT_TRUE(oracle.write(dir.path() / "coarse.bt"));
  const auto mismatch = readOracleLabels(dir.path() / "coarse.bt", 0.1);
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.error().message.find("resolution"), std::string::npos);
}

TEST(SimulatedSequence, BeamsReplaceTheSensorsTableEvenlyInTheFieldOfView) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "structured";
  o.sensor = "vlp16";
  o.columns = 64;
  o.scans = 1;
  o.beams = 24;
  o.top_deg = 10;
  o.bottom_deg = -10;
  o.ground_truth_resolution_m = 0;
  ASSERT_TRUE(writeSimulatedSequence(o, dir.path()));
  std::ifstream in(dir.path() / "sim.txt");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("beams 24\n"), std::string::npos) << text;
  EXPECT_NE(text.find("elevations_deg 10 -10\n"), std::string::npos) << text;
  o.beams = 1;
  EXPECT_FALSE(writeSimulatedSequence(o, dir.path()));
}

TEST(SimulatedSequence, SparseScansWithOracleLabelsOfTheSameSeenSpace) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "structured";
  o.sensor = "os0-64";
  o.columns = 256;
  o.max_range_m = 8.0;
  o.scans = 4;
  o.points_per_scan = 1500;
  o.oracle_factor = 2;
  o.oracle_resolutions = {0.2};
  o.ground_truth_resolution_m = 0;
  auto summary = writeSimulatedSequence(o, dir.path());
  ASSERT_TRUE(summary) << summary.error().message;
  EXPECT_EQ(summary->points, 4U * 1500U);
  ASSERT_EQ(summary->oracle_labels.size(), 1U);
  const auto labels = readOracleLabels(summary->oracle_labels[0], 0.2);
  ASSERT_TRUE(labels) << labels.error().message;
  std::size_t occupied = 0;
  std::set<std::uint64_t> occupied_keys;
  for (const LabelledVoxel& v : *labels) {
    if (v.occupied) occupied_keys.insert(v.key.packed());
  }
  occupied = occupied_keys.size();
  EXPECT_GT(occupied, 500U);
  EXPECT_GT(labels->size(), 3 * occupied) << "free space dominates a room";
  // Every sparse return lands in a voxel the dense oracle saw occupied (or next to one: the
  // sparse and dense beams hit the same surfaces at slightly different points).
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source);
  const VoxelGrid grid(0.2);
  std::size_t near = 0, total = 0;
  for (std::size_t i = 0; i < (*source)->size(); ++i) {
    for (const Point3f& p : (*(*source)->load(i)).pointsWorld()) {
      const VoxelKey k = *grid.pointToKey(p);
      bool found = false;
      for (int dz = -1; dz <= 1 && !found; ++dz) {
        for (int dy = -1; dy <= 1 && !found; ++dy) {
          for (int dx = -1; dx <= 1 && !found; ++dx) {
            const VoxelKey n{static_cast<std::uint16_t>(k.x + dx),
                             static_cast<std::uint16_t>(k.y + dy),
                             static_cast<std::uint16_t>(k.z + dz)};
            found = occupied_keys.contains(n.packed());
          }
        }
      }
      near += found ? 1 : 0;
      ++total;
    }
  }
  EXPECT_GT(static_cast<double>(near) / total, 0.99) << near << " of " << total;
}

}  // namespace
}  // namespace densemap
