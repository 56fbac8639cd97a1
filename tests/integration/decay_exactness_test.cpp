// A map that forgets (map.decay) against a plain reference after every scan: OctoMap's
// computeUpdate says which cells each scan frees and hits, a hash map of log-odds applies
// OctoMap's updates to them, and the decay rule is applied cell by cell in the reference's own
// loop (every tracked cell, each step on its own). The scene has people walking through it, so
// cells fall due, step and vanish while scans keep arriving; the distance field follows.
#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include <cmath>
#include <unordered_map>

#include "densemap/mapper/mapper.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "distance_field_reference.hpp"
#include "simulated_scans.hpp"

namespace densemap {
namespace {

struct KeyHash {
  std::size_t operator()(const octomap::OcTreeKey& k) const {
    return (std::size_t{k[0]} << 32) ^ (std::size_t{k[1]} << 16) ^ k[2];
  }
};

/// The map a decaying Mapper should hold, computed plainly.
class DecayReference {
 public:
  DecayReference(double resolution, double max_range, DecayOptions decay)
      : tree_(resolution), max_range_(max_range), decay_(decay) {}

  void insert(const PointCloud& points, const Point3f& origin, std::int64_t now_ms) {
    decayUntil(now_ms);
    octomap::Pointcloud cloud;
    for (const Point3f& p : points) cloud.push_back(p.x(), p.y(), p.z());
    octomap::KeySet free, occupied;
    tree_.computeUpdate(cloud, octomap::point3d(origin.x(), origin.y(), origin.z()), free,
                        occupied, max_range_);
    for (const auto& k : free) update(k, model_.miss());
    for (const auto& k : occupied) {
      update(k, model_.hit());
      due_[k] = now_ms + std::llround(decay_.after_s * 1e3);
    }
  }

  [[nodiscard]] const std::unordered_map<octomap::OcTreeKey, float, KeyHash>& cells() const {
    return cells_;
  }

 private:
  void update(const octomap::OcTreeKey& k, float delta) {
    const auto it = cells_.find(k);
    const float old = it == cells_.end() ? 0.0F : it->second;
    cells_[k] = model_.updateBy(old, delta);
  }

  void decayUntil(std::int64_t now_ms) {
    const std::int64_t period = std::llround(decay_.period_s * 1e3);
    for (auto it = due_.begin(); it != due_.end();) {
      auto cell = cells_.find(it->first);
      bool drop = cell == cells_.end() || !(cell->second > 0.0F);
      while (!drop && it->second <= now_ms) {
        cell->second = model_.updateBy(cell->second, model_.miss());
        if (!(cell->second > 0.0F)) {
          cells_.erase(cell);
          drop = true;
        }
        it->second += period;
      }
      it = drop ? due_.erase(it) : std::next(it);
    }
  }

  octomap::OcTree tree_;  // only its key arithmetic and computeUpdate
  double max_range_;
  DecayOptions decay_;
  SensorModel model_;
  std::unordered_map<octomap::OcTreeKey, float, KeyHash> cells_;
  std::unordered_map<octomap::OcTreeKey, std::int64_t, KeyHash> due_;
};

void expectEqualsReference(const Mapper& mapper, const DecayReference& ref,
                           const std::string& what) {
  ASSERT_EQ(mapper.knownCells(), ref.cells().size()) << what;
  const VoxelGrid grid(mapper.resolution());
  std::size_t differ = 0;
  mapper.forEachCell(CellFilter::kKnown, [&](const Point3f& centre, float v) {
    const auto key = grid.pointToKey(centre);
    ASSERT_TRUE(key);
    const auto it = ref.cells().find(octomap::OcTreeKey(key->x, key->y, key->z));
    if (it == ref.cells().end() || it->second != v) ++differ;
  });
  EXPECT_EQ(differ, 0U) << what;
}

TEST(DecayExactness, EqualsThePlainRuleAfterEveryScanWithWalkers) {
  test::TempDir dir;
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "os128";
  o.columns = 512;
  o.scans = 30;
  o.seed = 5;
  o.walkers = 3;
  o.ground_truth_resolution_m = 0;
  const auto scans = test::simulatedWorldScans(o, dir.path());
  ASSERT_EQ(scans.size(), 30U);

  // Short times, so cells fall due, step several times at once (a scan every 0.1 s, a step
  // every 0.04 s) and vanish within the sequence.
  const DecayOptions decay{.after_s = 0.5, .period_s = 0.04};
  const double res = 0.1, max_range = 20.0, max_distance = 0.6;
  MapperOptions m;
  m.resolution_m = res;
  m.max_range_m = max_range;
  m.threads = 2;
  m.decay = decay;
  m.distance_field = true;
  m.max_distance_m = max_distance;
  for (const bool versioned : {false, true}) {
    m.versioned_reads = versioned;
    auto mapper = Mapper::create(m);
    ASSERT_TRUE(mapper) << mapper.error().message;
    DecayReference ref(res, max_range, decay);
    std::size_t stepped = 0, erased = 0;
    for (std::size_t i = 0; i < scans.size(); ++i) {
      const std::int64_t now_ms = 100 * static_cast<std::int64_t>(i);
      auto r = mapper->insertPointCloud(scans[i].points, scans[i].origin, 0.001 * now_ms);
      ASSERT_TRUE(r) << r.error().message;
      stepped += r->decay_stepped_cells;
      erased += r->decay_erased_cells;
      ref.insert(scans[i].points, scans[i].origin, now_ms);
      const std::string what = (versioned ? "versioned, " : "") + std::string("after scan ") +
                               std::to_string(i);
      expectEqualsReference(*mapper, ref, what);
      if (i % 5 == 4) test::expectEqualsBruteForce(*mapper, max_distance, what);
    }
    EXPECT_GT(stepped, 1000U) << "the sequence should make cells decay";
    EXPECT_GT(erased, 1000U) << "the sequence should make cells vanish";
  }
}

TEST(DecayExactness, OffByDefaultAndRefusedWhereItCannotRun) {
  MapperOptions m;
  EXPECT_FALSE(m.decay.has_value());
  m.decay = DecayOptions{.after_s = 1.0, .period_s = 0.5};
  m.backend = "octree";
  auto octree = Mapper::create(m);
  ASSERT_FALSE(octree);
  EXPECT_NE(octree.error().message.find("decay"), std::string::npos) << octree.error().message;
  m.backend = "grid";
  m.kind = "akimap";
  EXPECT_FALSE(Mapper::create(m));
  m.kind = "log_odds";
  m.decay->period_s = 0.0;
  auto bad = Mapper::create(m);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("period_s"), std::string::npos) << bad.error().message;
  m.decay->period_s = 0.5;
  auto ok = Mapper::create(m);
  ASSERT_TRUE(ok) << ok.error().message;
  const PointCloud points{Point3f(1.0F, 0.0F, 0.0F)};
  EXPECT_FALSE(ok->insertPointCloud(points, Point3f::Zero(), std::nan("")));
  EXPECT_FALSE(ok->insertPointCloud(points, Point3f::Zero(), 1e10));
  EXPECT_TRUE(ok->insertPointCloud(points, Point3f::Zero(), 1.0));
}

}  // namespace
}  // namespace densemap
