// The in-process Mapper: its answers against the map it holds, read back by brute force; its
// files; its refusals; readers beside a writer.
#include "densemap/mapper/mapper.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <set>
#include <thread>

#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

MapperOptions options(double resolution_m = 0.2, double max_range_m = 8.0) {
  MapperOptions o;
  o.resolution_m = resolution_m;
  o.max_range_m = max_range_m;
  o.threads = 2;
  return o;
}

PointCloud scanAt(const Point3f& origin, std::uint64_t seed) {
  return test::adversarialScan(0.2, origin, 3000, 6.0, seed);
}

/// Every known cell as centre -> log-odds (the map as forEachCell gives it).
std::map<std::tuple<float, float, float>, float> cellsOf(const Mapper& m) {
  std::map<std::tuple<float, float, float>, float> cells;
  m.forEachCell(CellFilter::kKnown, [&](const Point3f& c, float v) {
    cells[{c.x(), c.y(), c.z()}] = v;
  });
  return cells;
}

TEST(Mapper, QueriesAnswerWhatTheMapHolds) {
  auto mapper = Mapper::create(options());
  ASSERT_TRUE(mapper) << mapper.error().message;
  auto r = mapper->insertPointCloud(scanAt(Point3f::Zero(), 7), Point3f::Zero());
  ASSERT_TRUE(r) << r.error().message;
  EXPECT_EQ(r->version, 1U);
  EXPECT_EQ(mapper->version(), 1U);
  EXPECT_FALSE(r->changed_blocks.empty());
  const auto cells = cellsOf(*mapper);
  ASSERT_EQ(cells.size(), mapper->knownCells());
  std::size_t occupied = 0;
  std::vector<float> xyz;
  for (const auto& [c, v] : cells) {
    const Point3f p(std::get<0>(c), std::get<1>(c), std::get<2>(c));
    const CellInfo info = mapper->query(p);
    ASSERT_TRUE(info.log_odds);
    EXPECT_EQ(*info.log_odds, v);
    EXPECT_EQ(info.state, v > 0 ? CellState::kOccupied : CellState::kFree);
    EXPECT_NEAR(info.probability(), 1.0 / (1.0 + std::exp(-static_cast<double>(v))), 1e-12);
    occupied += v > 0;
    xyz.insert(xyz.end(), {p.x(), p.y(), p.z()});
  }
  ASSERT_GT(occupied, 0U);
  // The batched query equals the single one.
  std::vector<float> log_odds(cells.size());
  std::vector<CellState> states(cells.size());
  ASSERT_TRUE(mapper->query(xyz, log_odds, states));
  std::size_t i = 0;
  for (const auto& [c, v] : cells) {
    EXPECT_EQ(log_odds[i], v);
    EXPECT_EQ(states[i], v > 0 ? CellState::kOccupied : CellState::kFree);
    ++i;
  }
  // Far away: unknown; NaN: unknown, not an error.
  EXPECT_EQ(mapper->query(Point3f(500, 500, 500)).state, CellState::kUnknown);
  EXPECT_FALSE(mapper->query(Point3f(NAN, 0, 0)).log_odds);
  EXPECT_EQ(mapper->query(Point3f(500, 0, 0)).probability(), 0.5);

  // A box: its counts and the cells forEachCell visits equal a brute-force walk of the map.
  const Point3f lo(-2.1F, -1.3F, -0.7F), hi(3.3F, 2.2F, 1.1F);
  const auto counts = mapper->queryBox(lo, hi);
  ASSERT_TRUE(counts);
  std::size_t in_occ = 0, in_free = 0, visited_occ = 0;
  // A cell is in the box when its index (floor(coordinate / resolution)) lies between the
  // corners' on every axis.
  const auto index = [](float coordinate) { return std::floor(coordinate / 0.2); };
  for (const auto& [c, v] : cells) {
    const float xyz_c[3] = {std::get<0>(c), std::get<1>(c), std::get<2>(c)};
    bool inside = true;
    for (int a = 0; a < 3; ++a) {
      inside = inside && index(xyz_c[a]) >= index(lo[a]) && index(xyz_c[a]) <= index(hi[a]);
    }
    if (inside) (v > 0 ? in_occ : in_free) += 1;
  }
  EXPECT_EQ(counts->occupied, in_occ);
  EXPECT_EQ(counts->free, in_free);
  ASSERT_TRUE(mapper->forEachCell(lo, hi, CellFilter::kOccupied, [&](const Point3f& c, float v) {
    EXPECT_GT(v, 0.0F);
    EXPECT_EQ(*mapper->query(c).log_odds, v);
    ++visited_occ;
  }));
  EXPECT_EQ(visited_occ, in_occ);
  // A changed block's box holds cells.
  const auto [bmin, bmax] = mapper->blockBox(r->changed_blocks.front());
  EXPECT_NEAR((bmax - bmin).x(), 8 * 0.2, 1e-4);
  std::size_t in_block = 0;
  ASSERT_TRUE(mapper->forEachCell(bmin + Point3f::Constant(0.05F), bmax - Point3f::Constant(0.05F),
                                  CellFilter::kKnown, [&](const Point3f&, float) { ++in_block; }));
  EXPECT_GT(in_block, 0U);
}

TEST(Mapper, RayHitsTheFirstOccupiedCell) {
  auto mapper = Mapper::create(options(0.1, 20.0));
  ASSERT_TRUE(mapper);
  // A wall at x = 5: rays from the origin.
  PointCloud wall;
  for (float y = -2; y <= 2; y += 0.05F) {
    for (float z = -1; z <= 1; z += 0.05F) wall.emplace_back(5.0F, y, z);
  }
  ASSERT_TRUE(mapper->insertPointCloud(wall, Point3f::Zero()));
  const auto hit = mapper->castRay(Point3f::Zero(), Point3f(1e-7F, 0, 0), 10.0F);
  ASSERT_TRUE(hit) << hit.error().message;
  EXPECT_TRUE(hit->hit);
  EXPECT_NEAR(hit->center.x(), 5.05, 0.051);
  EXPECT_EQ(mapper->query(hit->center).state, CellState::kOccupied);
  // A direction is judged by its own scale: tiny and huge ones point as well as unit ones.
  for (const float scale : {1e-30F, 1e30F}) {
    const auto scaled = mapper->castRay(Point3f::Zero(), Point3f(scale, 0, 0), 10.0F);
    ASSERT_TRUE(scaled) << scale << ": " << scaled.error().message;
    EXPECT_EQ(scaled->center, hit->center);
  }
  const auto miss = mapper->castRay(Point3f::Zero(), Point3f(-1, 0, 0), 10.0F);
  ASSERT_TRUE(miss);
  EXPECT_FALSE(miss->hit);
  EXPECT_FALSE(mapper->castRay(Point3f::Zero(), Point3f(0, 0, 0), 10.0F));
  EXPECT_FALSE(mapper->castRay(Point3f::Zero(), Point3f(1, 0, 0), -1.0F));
}

TEST(Mapper, InsertScanEqualsInsertPointCloudOfTheTransformedPoints) {
  const PointCloud sensor = scanAt(Point3f::Zero(), 11);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.rotate(Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.2, 0.3, 1).normalized()));
  T.translation() = Eigen::Vector3d(1.25, -0.5, 0.3);
  auto a = Mapper::create(options());
  auto b = Mapper::create(options());
  ASSERT_TRUE(a && b);
  ASSERT_TRUE(a->insertScan(sensor, T));
  PointCloud world;
  for (const Point3f& p : sensor) world.push_back((T * p.cast<double>()).cast<float>());
  ASSERT_TRUE(b->insertPointCloud(world, T.translation().cast<float>()));
  EXPECT_EQ(cellsOf(*a), cellsOf(*b));
  EXPECT_GT(a->knownCells(), 0U);
  // A pose that is not rigid is refused.
  Eigen::Isometry3d bad = T;
  bad.matrix()(0, 0) = 3.0;
  EXPECT_FALSE(a->insertScan(sensor, bad));
}

TEST(Mapper, RefusesBadOptionsAndBadScansAndKeepsTheMap) {
  for (const auto& [edit, needle] :
       std::vector<std::pair<std::function<void(MapperOptions&)>, std::string>>{
           {[](MapperOptions& o) { o.resolution_m = 0; }, "resolution_m"},
           {[](MapperOptions& o) { o.resolution_m = NAN; }, "resolution_m"},
           {[](MapperOptions& o) { o.max_range_m = NAN; }, "max_range_m"},
           {[](MapperOptions& o) { o.max_range_m = 1e6; }, "max_range_m"},
           {[](MapperOptions& o) { o.kind = "magic"; }, "unknown kind 'magic'"},
           {[](MapperOptions& o) { o.backend = "hash"; }, "backend"},
           {[](MapperOptions& o) { o.integration = "fast"; }, "integration"},
           {[](MapperOptions& o) { o.sensor.hit = 0.3; }, "sensor"},
           {[](MapperOptions& o) { o.threads = -1; }, "threads"},
           {[](MapperOptions& o) {
              o.keep_radius_m = 10;
              o.backend = "octree";
            },
            "grid"},
           {[](MapperOptions& o) { o.bounds = std::pair(Point3f(1, 1, 1), Point3f(0, 2, 2)); },
            "bounds"}}) {
    MapperOptions o = options();
    edit(o);
    auto m = Mapper::create(o);
    ASSERT_FALSE(m) << needle;
    EXPECT_NE(m.error().message.find(needle), std::string::npos) << m.error().message;
  }
  auto mapper = Mapper::create(options());
  ASSERT_TRUE(mapper);
  ASSERT_TRUE(mapper->insertPointCloud(scanAt(Point3f::Zero(), 3), Point3f::Zero()));
  const auto before = cellsOf(*mapper);
  PointCloud nan_scan = scanAt(Point3f::Zero(), 4);
  nan_scan[17] = Point3f(1, NAN, 0);
  auto r = mapper->insertPointCloud(nan_scan, Point3f::Zero());
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("point 17 is NaN or Inf"), std::string::npos);
  EXPECT_FALSE(mapper->insertPointCloud(PointCloud{}, Point3f::Zero()));
  EXPECT_FALSE(mapper->insertPointCloud(scanAt(Point3f::Zero(), 5), Point3f(INFINITY, 0, 0)));
  const std::vector<float> seven(7, 1.0F);
  EXPECT_FALSE(mapper->insertPointCloud(std::span<const float>(seven), Point3f::Zero()));
  MapperOptions small = options();
  small.max_points = 10;
  auto limited = Mapper::create(small);
  ASSERT_TRUE(limited);
  auto big = limited->insertPointCloud(scanAt(Point3f::Zero(), 5), Point3f::Zero());
  ASSERT_FALSE(big);
  EXPECT_NE(big.error().message.find("exceed the limit of 10"), std::string::npos);
  EXPECT_EQ(cellsOf(*mapper), before);
  EXPECT_EQ(mapper->version(), 1U);
}

TEST(Mapper, SavesAndLoadsDmapBtAndOt) {
  test::TempDir dir;
  auto mapper = Mapper::create(options());
  ASSERT_TRUE(mapper);
  for (std::uint64_t s = 0; s < 3; ++s) {
    ASSERT_TRUE(
        mapper->insertPointCloud(scanAt(Point3f(0.3F * s, 0, 0), 20 + s), Point3f(0.3F * s, 0, 0)));
  }
  const auto cells = cellsOf(*mapper);
  for (const std::string name : {"map.dmap", "map.ot"}) {
    const auto path = (dir.path() / name).string();
    auto bytes = mapper->save(path);
    ASSERT_TRUE(bytes) << bytes.error().message;
    auto back = Mapper::load(path, options());
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(cellsOf(*back), cells) << name;
    EXPECT_EQ(back->resolution(), 0.2);
    if (name == "map.dmap") EXPECT_EQ(back->version(), mapper->version());
  }
  // .bt keeps occupied / free: every cell's state.
  const auto bt = (dir.path() / "map.bt").string();
  ASSERT_TRUE(mapper->save(bt));
  auto back = Mapper::load(bt, options());
  ASSERT_TRUE(back);
  ASSERT_EQ(back->knownCells(), cells.size());
  for (const auto& [c, v] : cells) {
    const Point3f p(std::get<0>(c), std::get<1>(c), std::get<2>(c));
    EXPECT_EQ(back->query(p).state, mapper->query(p).state);
  }
  // A loaded map takes scans as the original does.
  auto original = Mapper::load((dir.path() / "map.dmap").string(), options());
  ASSERT_TRUE(original);
  ASSERT_TRUE(original->insertPointCloud(scanAt(Point3f(1, 0, 0), 40), Point3f(1, 0, 0)));
  ASSERT_TRUE(mapper->insertPointCloud(scanAt(Point3f(1, 0, 0), 40), Point3f(1, 0, 0)));
  EXPECT_EQ(cellsOf(*original), cellsOf(*mapper));
  // Missing and foreign files: refused, naming the file.
  auto missing = Mapper::load((dir.path() / "none.dmap").string());
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("none.dmap"), std::string::npos);
}

TEST(Mapper, DenseKindResumesFromItsSnapshotAsIfNeverStopped) {
  test::TempDir dir;
  MapperOptions o = options(0.2, 8.0);
  o.kind = "akimap_rays";
  auto whole = Mapper::create(o);
  auto first = Mapper::create(o);
  ASSERT_TRUE(whole && first) << (whole ? "" : whole.error().message);
  for (std::uint64_t s = 0; s < 2; ++s) {
    ASSERT_TRUE(whole->insertPointCloud(scanAt(Point3f::Zero(), 60 + s), Point3f::Zero()));
    ASSERT_TRUE(first->insertPointCloud(scanAt(Point3f::Zero(), 60 + s), Point3f::Zero()));
  }
  const auto path = (dir.path() / "dense.dmap").string();
  ASSERT_TRUE(first->save(path));
  MapperOptions plain = options(0.2, 8.0);  // the file says the kind
  auto resumed = Mapper::load(path, plain);
  ASSERT_TRUE(resumed) << resumed.error().message;
  EXPECT_EQ(resumed->options().kind, "akimap_rays");
  ASSERT_TRUE(whole->insertPointCloud(scanAt(Point3f::Zero(), 62), Point3f::Zero()));
  ASSERT_TRUE(resumed->insertPointCloud(scanAt(Point3f::Zero(), 62), Point3f::Zero()));
  EXPECT_EQ(cellsOf(*resumed), cellsOf(*whole));
  EXPECT_GT(whole->knownCells(), 0U);
}

TEST(Mapper, ClearAndClearBoxForgetCells) {
  auto mapper = Mapper::create(options());
  ASSERT_TRUE(mapper);
  ASSERT_TRUE(mapper->insertPointCloud(scanAt(Point3f::Zero(), 9), Point3f::Zero()));
  const std::size_t known = mapper->knownCells();
  auto erased = mapper->clearBox(Point3f(-1, -1, -1), Point3f(1, 1, 1));
  ASSERT_TRUE(erased);
  EXPECT_GT(*erased, 0U);
  EXPECT_EQ(mapper->knownCells(), known - *erased);
  EXPECT_EQ(mapper->queryBox(Point3f(-0.9F, -0.9F, -0.9F), Point3f(0.9F, 0.9F, 0.9F))->free, 0U);
  EXPECT_FALSE(mapper->clearBox(Point3f(1, 1, 1), Point3f(0, 0, 0)));
  mapper->clear();
  EXPECT_EQ(mapper->knownCells(), 0U);
  EXPECT_EQ(mapper->version(), 3U);
}

TEST(Mapper, BothReadModesGiveTheSameMapsVersionsAndChangedBlocks) {
  for (const std::string kind : {"log_odds", "akimap_rays"}) {
    for (const std::string backend : {"grid", "octree"}) {
      if (kind != "log_odds" && backend == "octree") continue;
      MapperOptions in_place = options();
      in_place.kind = kind;
      in_place.backend = backend;
      MapperOptions versioned = in_place;
      versioned.versioned_reads = true;
      auto a = Mapper::create(in_place);
      auto b = Mapper::create(versioned);
      ASSERT_TRUE(a && b);
      for (std::uint64_t s = 0; s < 4; ++s) {
        const Point3f origin(0.4F * s, 0.1F * s, 0);
        auto ra = a->insertPointCloud(scanAt(origin, 90 + s), origin);
        auto rb = b->insertPointCloud(scanAt(origin, 90 + s), origin);
        ASSERT_TRUE(ra && rb);
        EXPECT_EQ(ra->version, rb->version);
        std::sort(ra->changed_blocks.begin(), ra->changed_blocks.end());
        std::sort(rb->changed_blocks.begin(), rb->changed_blocks.end());
        ra->changed_blocks.erase(std::unique(ra->changed_blocks.begin(), ra->changed_blocks.end()),
                                 ra->changed_blocks.end());
        rb->changed_blocks.erase(std::unique(rb->changed_blocks.begin(), rb->changed_blocks.end()),
                                 rb->changed_blocks.end());
        EXPECT_EQ(ra->changed_blocks, rb->changed_blocks)
            << kind << "/" << backend << " scan " << s;
        EXPECT_FALSE(ra->changed_blocks.empty());
        EXPECT_EQ(cellsOf(*a), cellsOf(*b)) << kind << "/" << backend << " scan " << s;
      }
      // A changed block is one whose cells differ from the version before: check the last scan's
      // list against the cells by brute force (no block outside the list changed).
      const auto before = cellsOf(*a);
      const Point3f origin(2.0F, 0, 0);
      auto r = a->insertPointCloud(scanAt(origin, 99), origin);
      ASSERT_TRUE(r);
      const auto after = cellsOf(*a);
      std::set<std::uint64_t> listed(r->changed_blocks.begin(), r->changed_blocks.end());
      std::set<std::tuple<float, float, float>> differing;
      for (const auto& [c, v] : after) {
        const auto it = before.find(c);
        if (it == before.end() || it->second != v) differing.insert(c);
      }
      for (const auto& [c, v] : before) {
        if (!after.contains(c)) differing.insert(c);
      }
      ASSERT_FALSE(differing.empty());
      for (const auto& c : differing) {
        bool in_a_listed_block = false;
        for (const std::uint64_t key : listed) {
          const auto [lo, hi] = a->blockBox(key);
          const Point3f p(std::get<0>(c), std::get<1>(c), std::get<2>(c));
          in_a_listed_block = in_a_listed_block ||
                              ((p.array() > lo.array()).all() && (p.array() < hi.array()).all());
        }
        ASSERT_TRUE(in_a_listed_block)
            << kind << "/" << backend << ": a changed cell's block is not listed";
      }
    }
  }
}

TEST(Mapper, ReadersSeeWholeVersionsWhileAWriterInserts) {
  for (const bool versioned : {false, true}) {
    MapperOptions o = options();
    o.versioned_reads = versioned;
    auto mapper = Mapper::create(o);
    ASSERT_TRUE(mapper);
    std::atomic<bool> done{false};
    std::atomic<std::size_t> reads{0};
    std::thread reader([&] {
      std::uint64_t last = 0;
      while (!done.load()) {
        const std::uint64_t v = mapper->version();
        EXPECT_GE(v, last);
        last = v;
        (void)mapper->query(Point3f(1, 0, 0));
        (void)mapper->queryBox(Point3f(-2, -2, -2), Point3f(2, 2, 2));
        ++reads;
      }
    });
    for (std::uint64_t s = 0; s < 8; ++s) {
      ASSERT_TRUE(mapper->insertPointCloud(scanAt(Point3f(0.1F * s, 0, 0), 80 + s),
                                           Point3f(0.1F * s, 0, 0)));
    }
    done = true;
    reader.join();
    EXPECT_EQ(mapper->version(), 8U);
    EXPECT_GT(reads.load(), 0U);
  }
}

}  // namespace
}  // namespace densemap
