#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <sstream>

#include "densemap/io/scan_source.hpp"
#include "densemap/sim/ground_truth.hpp"
#include "densemap/sim/lidar_simulator.hpp"
#include "densemap/sim/primitive_scene.hpp"
#include "densemap/sim/procedural_scenes.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/sim/trajectory.hpp"
#include "densemap/sim/walker_scene.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap {
namespace {

Scan simulate(const std::string& scene_name, const std::string& sensor, unsigned seed, int threads,
              double noise = 0.0, double dropout = 0.0) {
  auto scene = makeScene(scene_name, seed);
  auto lidar = lidarPreset(sensor);
  lidar->columns = 360;
  lidar->noise_std_m = noise;
  lidar->dropout = dropout;
  const auto poses = trajectoryAlong(scene->waypoints, 3);
  tbb::task_arena arena(threads);
  Scan scan;
  arena.execute([&] { scan = simulateScan(*scene->scene, *lidar, poses[1], 1, seed); });
  return scan;
}

TEST(LidarSimulator, IsDeterministicForASeedWhateverTheThreadCount) {
  const Scan a = simulate("outdoor", "hdl64", 7, 1, 0.02, 0.1);
  const Scan b = simulate("outdoor", "hdl64", 7, 2, 0.02, 0.1);
  ASSERT_GT(a.points.size(), 1000U);
  EXPECT_EQ(a.points, b.points);
  EXPECT_EQ(a.intensities, b.intensities);
  const Scan c = simulate("outdoor", "hdl64", 8, 2, 0.02, 0.1);
  EXPECT_NE(a.points, c.points);
}

TEST(LidarSimulator, RangesRespectTheSensorAndDropoutsRemovePoints) {
  auto lidar = lidarPreset("vlp16");
  const Scan clean = simulate("indoor", "vlp16", 3, 2);
  EXPECT_EQ(clean.points.size(), 16U * 360U);  // an enclosed room returns every beam
  for (const auto& p : clean.points) {
    EXPECT_GE(p.norm(), lidar->min_range_m - 1e-4);
    EXPECT_LE(p.norm(), lidar->max_range_m + 1e-4);
  }
  const Scan dropped = simulate("indoor", "vlp16", 3, 2, 0.0, 0.5);
  EXPECT_LT(dropped.points.size(), clean.points.size() * 6 / 10);
  EXPECT_GT(dropped.points.size(), clean.points.size() * 4 / 10);
}

TEST(LidarSimulator, HitsAnalyticSurfacesExactly) {
  PrimitiveScene scene(
      Eigen::AlignedBox3d(Eigen::Vector3d(-10, -10, -1), Eigen::Vector3d(10, 10, 5)));
  scene.add(BoxShape{Eigen::Vector3d(-50, -50, -1), Eigen::Vector3d(50, 50, 0)});  // ground z = 0
  LidarModel lidar{"test", {-10.0, -20.0}, 90};
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(0, 0, 2);
  const Scan scan = simulateScan(scene, lidar, T, 0, 1);
  ASSERT_EQ(scan.points.size(), 180U);
  for (const Point3f& p : transformPoints(T, scan.points)) EXPECT_NEAR(p.z(), 0.0, 1e-5);
}

TEST(Walkers, PaceBesideThePathAndRaysMeetTheNearerSurface) {
  std::vector<Transform> poses(11, Transform::Identity());
  for (int i = 0; i < 11; ++i) poses[i].translation() = Eigen::Vector3d(i, 0, 1.5);
  // One walker, centred at the middle pose, 2.5 m to the left of the path (+y), starting at
  // the back end of its 16 m: 1.4 m/s along +x, turning at the far end.
  auto w = walkersAt(poses, 1, 0.0);
  ASSERT_EQ(w.size(), 1U);
  EXPECT_NEAR(w[0].center_xy.x(), 5.0 - 8.0, 1e-9);
  EXPECT_NEAR(w[0].center_xy.y(), 2.5, 1e-9);
  EXPECT_NEAR(walkersAt(poses, 1, 1.0)[0].center_xy.x(), 5.0 - 8.0 + 1.4, 1e-9);
  EXPECT_NEAR(walkersAt(poses, 1, 16.0 / 1.4 + 1.0)[0].center_xy.x(), 5.0 + 8.0 - 1.4, 1e-9);
  EXPECT_EQ(walkersAt(poses, 2, 0.0)[1].center_xy.y(), -2.5) << "the sides alternate";
  EXPECT_TRUE(walkersAt(poses, 0, 0.0).empty());

  PrimitiveScene room(Eigen::AlignedBox3d(Eigen::Vector3d(-20, -20, -1), Eigen::Vector3d(20, 20, 5)));
  room.add(BoxShape{Eigen::Vector3d(-20, 10, 0), Eigen::Vector3d(20, 11, 3)});  // a wall at y = 10
  const WalkerScene scene(room, walkersAt(poses, 1, 0.0));
  const Eigen::Vector3d origin(-3.0, 0.0, 1.0);
  // Towards +y the walker (at y = 2.5, radius 0.25) comes before the wall; beside it, the wall.
  EXPECT_NEAR(*scene.castRay(origin, Eigen::Vector3d::UnitY(), 50.0), 2.25, 1e-9);
  EXPECT_NEAR(*room.castRay(origin, Eigen::Vector3d::UnitY(), 50.0), 10.0, 1e-9);
  const Eigen::Vector3d beside(-1.0, 0.0, 1.0);
  EXPECT_NEAR(*scene.castRay(beside, Eigen::Vector3d::UnitY(), 50.0), 10.0, 1e-9);
  // Above its head the walker is not there; the ground truth is the static room's.
  EXPECT_NEAR(*scene.castRay(Eigen::Vector3d(-3, 0, 2.0), Eigen::Vector3d::UnitY(), 50.0), 10.0,
              1e-9);
  EXPECT_FALSE(scene.overlapsBox(Eigen::Vector3d(-3.1, 2.4, 0.5), Eigen::Vector3d(-2.9, 2.6, 0.7)));
}

TEST(BeamTables, MatchTheRealSensors) {
  EXPECT_EQ(lidarPreset("vlp16")->beams(), 16);
  EXPECT_EQ(lidarPreset("hdl64")->beams(), 64);
  EXPECT_EQ(lidarPreset("os128")->beams(), 128);
  EXPECT_DOUBLE_EQ(lidarPreset("vlp16")->elevations_deg.front(), 15.0);
  EXPECT_DOUBLE_EQ(lidarPreset("hdl64")->elevations_deg.back(), -24.33);
  EXPECT_FALSE(lidarPreset("lidar9000"));
  LidarModel bad = *lidarPreset("vlp16");
  bad.dropout = 1.5;
  EXPECT_FALSE(bad.validate());
}

TEST(GroundTruth, LabelsSolidsOccupiedAndTheRestFree) {
  PrimitiveScene scene(Eigen::AlignedBox3d(Eigen::Vector3d(-2, -2, -2), Eigen::Vector3d(2, 2, 2)));
  scene.add(BoxShape{Eigen::Vector3d(0.0, 0.0, 0.0), Eigen::Vector3d(0.5, 0.5, 0.5)});
  scene.add(SphereShape{Eigen::Vector3d(-1, -1, -1), 0.3});
  const auto tree = groundTruthOcTree(scene, 0.1, scene.bounds());
  std::size_t occupied = 0, free = 0;
  for (auto it = tree->begin_leafs(), end = tree->end_leafs(); it != end; ++it) {
    const double cells = std::pow(it.getSize() / 0.1, 3);
    (tree->isNodeOccupied(*it) ? occupied : free) += static_cast<std::size_t>(std::lround(cells));
  }
  // 5^3 box cells plus the sphere's (about 4/3 pi 3^3 = 113, more with partial overlaps).
  EXPECT_GT(occupied, 125U + 100U);
  EXPECT_LT(occupied, 125U + 260U);
  EXPECT_EQ(occupied + free, 40U * 40U * 40U);
  EXPECT_TRUE(tree->isNodeOccupied(tree->search(0.25, 0.25, 0.25)));
  EXPECT_FALSE(tree->isNodeOccupied(tree->search(0.55, 0.25, 0.25)));
  EXPECT_TRUE(tree->isNodeOccupied(tree->search(-1.0, -1.0, -1.0)));
  EXPECT_EQ(tree->search(2.05, 0.0, 0.0), nullptr);  // outside the bounds: unknown
}

TEST(SimulatedSequence, WritesADatasetWhosePointsLieInOccupiedTruth) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = 512;
  o.scans = 3;
  o.ground_truth_resolution_m = 0.1;
  auto summary = writeSimulatedSequence(o, dir.path());
  ASSERT_TRUE(summary) << summary.error().message;
  EXPECT_EQ(summary->scans, 3U);
  auto source = openScanSource(dir.path());
  ASSERT_TRUE(source);
  ASSERT_EQ((*source)->size(), 3U);
  octomap::OcTree truth(0.1);
  ASSERT_TRUE(truth.readBinary(summary->ground_truth.string()));
  std::size_t inside = 0, total = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const Scan scan = *(*source)->load(i);
    const Point3f origin = scan.originWorld();
    for (const Point3f& p : scan.pointsWorld()) {
      ++total;
      // Surfaces here lie on voxel faces; the solid is just behind the return, along the ray.
      const Point3f q = p + (p - origin).normalized() * 0.005F;
      const auto* node = truth.search(q.x(), q.y(), q.z());
      if (node != nullptr && truth.isNodeOccupied(node)) ++inside;
    }
  }
  // Noise-free returns lie on surfaces; only grazing rays at a solid's edge may miss it.
  EXPECT_GT(static_cast<double>(inside) / total, 0.99) << inside << " of " << total;
}

TEST(SimulatedSequence, RejectsBadOptionsWithClearErrors) {
  test::TempDir dir;
  SequenceOptions o;
  o.scans = 0;
  EXPECT_FALSE(writeSimulatedSequence(o, dir.path()));
  o.scans = 1;
  o.sensor = "nope";
  EXPECT_FALSE(writeSimulatedSequence(o, dir.path()));
  o.sensor = "vlp16";
  o.scene = (dir.path() / "missing.bt").string();
  auto missing = writeSimulatedSequence(o, dir.path());
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("missing.bt"), std::string::npos);
}

TEST(OctreeScene, Geb079IsAScene) {
  DENSEMAP_REQUIRE_DATA(geb, "octomap/geb079.bt");
  auto scene = makeScene(geb.string(), 1);
  ASSERT_TRUE(scene) << scene.error().message;
  auto lidar = lidarPreset("vlp16");
  lidar->columns = 256;
  const auto poses = trajectoryAlong(scene->waypoints, 2);
  const Scan scan = simulateScan(*scene->scene, *lidar, poses[0], 0, 1);
  EXPECT_GT(scan.points.size(), 16U * 256U / 2);
}

}  // namespace
}  // namespace densemap
