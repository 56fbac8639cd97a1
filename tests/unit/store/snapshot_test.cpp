// Snapshot files (core/store): .dmap round trips and clear errors; OctoMap .ot/.bt written from
// every map kind are read by OctoMap itself (AbstractOcTree::read, OcTree::readBinary) with the
// right type, resolution and every cell's value (kernel maps: their probabilities, unclamped).
#include <gtest/gtest.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/OcTree.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <thread>

#include "densemap/kernel/kernel_map.hpp"
#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/server/ingest.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/random_rays.hpp"

namespace densemap {
namespace {

TEST(Snapshot, SaveThenLoadIsTheSameMapAndVersionOnBothBackends) {
  test::TempDir dir;
  GridMap map(0.1, SensorModel{});
  Integrator integrator({.max_range_m = 4.0});
  for (int s = 0; s < 3; ++s) {
    const Point3f o(0.3F * s, 0, 0);
    integrator.integrate(map, test::adversarialScan(0.1, o, 4000, 4.0, s), o);
  }
  const auto view = MapView::fromMap(map, 17);
  const auto file = dir.path() / "m.dmap";
  auto saved = saveSnapshot(*view, map.sensorModel(), Backend::kGrid, file);
  ASSERT_TRUE(saved) << saved.error().message;
  EXPECT_EQ(*saved, std::filesystem::file_size(file));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename(), "m.dmap") << "left behind: " << entry.path();
  }
  for (const Backend backend : {Backend::kGrid, Backend::kOctree}) {
    auto loaded = loadSnapshot(file, backend, 0.1);
    ASSERT_TRUE(loaded) << loaded.error().message;
    EXPECT_EQ(loaded->version, 17U);
    EXPECT_EQ(diffMaps(*loaded->map, map).differing(), 0U);
  }
  EXPECT_FALSE(loadSnapshot(file, Backend::kGrid, 0.2));  // resolution mismatch
}

/// Every shorter cut of `file` (written into `dir`) is refused by loadSnapshot (no prefix of a
/// snapshot parses as one); returns the file's bytes.
std::string expectEveryCutRefused(const std::filesystem::path& file,
                                  const std::filesystem::path& dir) {
  std::string whole;
  {
    std::ifstream in(file, std::ios::binary);
    whole.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  for (std::size_t cut = 0; cut < whole.size(); ++cut) {
    std::ofstream(dir / "cut.dmap", std::ios::binary) << whole.substr(0, cut);
    EXPECT_FALSE(loadSnapshot(dir / "cut.dmap", Backend::kGrid, 0.0)) << "cut at " << cut;
  }
  return whole;
}

TEST(Snapshot, BrokenFilesAreClearErrors) {
  test::TempDir dir;
  GridMap map(0.2, SensorModel{});
  map.setLogOdds(VoxelKey{1, 2, 3}, 1.0F);
  map.setLogOdds(VoxelKey{4, 5, 6}, -1.0F);
  const auto file = dir.path() / "m.dmap";
  ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), map.sensorModel(), Backend::kGrid, file));
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 5);
  auto truncated = loadSnapshot(file, Backend::kGrid, 0.0);
  ASSERT_FALSE(truncated);
  EXPECT_NE(truncated.error().message.find("m.dmap"), std::string::npos);
  // Every shorter cut of a snapshot is refused (no prefix of the file parses as a snapshot).
  ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), map.sensorModel(), Backend::kGrid, file));
  expectEveryCutRefused(file, dir.path());
  std::ofstream(dir.path() / "junk.dmap") << "not a snapshot at all";
  EXPECT_FALSE(loadSnapshot(dir.path() / "junk.dmap", Backend::kGrid, 0.0));
  EXPECT_FALSE(loadSnapshot(dir.path() / "none.dmap", Backend::kGrid, 0.0));
}

TEST(Snapshot, NonFiniteLogOddsAreRefusedEvenWithAValidCrc) {
  test::TempDir dir;
  for (const float bad :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
        -std::numeric_limits<float>::infinity()}) {
    GridMap map(0.2, SensorModel{});
    map.setLogOdds(VoxelKey{1, 2, 3}, 1.0F);
    map.setLogOdds(VoxelKey{4, 5, 6}, bad);
    const auto file = dir.path() / "bad.dmap";
    ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), map.sensorModel(), Backend::kGrid, file));
    for (const Backend backend : {Backend::kGrid, Backend::kOctree}) {
      auto loaded = loadSnapshot(file, backend, 0.0);
      ASSERT_FALSE(loaded) << bad;
      EXPECT_NE(loaded.error().message.find("bad.dmap"), std::string::npos);
      EXPECT_NE(loaded.error().message.find("non-finite log-odds"), std::string::npos)
          << loaded.error().message;
    }
  }
}

TEST(Snapshot, ALogOddsMapOutsideItsClampRangeIsRefusedAnUnclampedOneIsNot) {
  test::TempDir dir;
  const SensorModel model;
  for (const float bad : {model.clampMax() + 0.5F, model.clampMin() - 0.01F, 100.0F}) {
    GridMap map(0.2, model);
    map.setLogOdds(VoxelKey{1, 2, 3}, model.clampMax());  // the bounds themselves are fine
    map.setLogOdds(VoxelKey{7, 2, 3}, model.clampMin());
    map.setLogOdds(VoxelKey{4, 5, 6}, bad);
    const auto file = dir.path() / "clamp.dmap";
    ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), model, Backend::kGrid, file));
    auto loaded = loadSnapshot(file, Backend::kGrid, 0.0);
    ASSERT_FALSE(loaded) << bad;
    EXPECT_NE(loaded.error().message.find("clamp.dmap"), std::string::npos);
    EXPECT_NE(loaded.error().message.find("outside the sensor model's clamp range"),
              std::string::npos)
        << loaded.error().message;
    // The same values saved as unclamped (a client's copy of a dense map): finite, so loaded.
    ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), model, Backend::kGrid, file, nullptr,
                             SnapshotValues::kUnclamped));
    auto unclamped = loadSnapshot(file, Backend::kGrid, 0.0);
    ASSERT_TRUE(unclamped) << unclamped.error().message;
    EXPECT_EQ((*unclamped).map->logOdds(VoxelKey{4, 5, 6}), bad);
  }
  // A sensor model that is not one (prob_hit below 0.5) is refused before any cell.
  GridMap map(0.2, SensorModel(SensorProbabilities{0.3, 0.4, 0.1192, 0.971}));
  map.setLogOdds(VoxelKey{1, 2, 3}, 0.5F);
  const auto file = dir.path() / "model.dmap";
  ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 1), map.sensorModel(), Backend::kGrid, file));
  auto loaded = loadSnapshot(file, Backend::kGrid, 0.0);
  ASSERT_FALSE(loaded);
  EXPECT_NE(loaded.error().message.find("sensor model is invalid"), std::string::npos)
      << loaded.error().message;
}

/// A map with `cells` known cells valued by `version`, as a view at `version`.
std::shared_ptr<const MapView> versionedView(std::uint64_t version, int cells = 50) {
  GridMap map(0.1, SensorModel{});
  for (int i = 0; i < cells; ++i) {
    map.setLogOdds(VoxelKey{static_cast<std::uint16_t>(32768 + i), 32768, 32768},
                   0.01F * static_cast<float>(version));
  }
  return MapView::fromMap(map, version);
}

TEST(SnapshotGenerations, SavesKeepTheLastKAndLoadingSkipsCorruptOnes) {
  test::TempDir dir;
  const auto path = dir.path() / "map.dmap";
  auto none = loadNewestSnapshot(path, 3, Backend::kGrid, 0.0);
  ASSERT_TRUE(none);
  EXPECT_FALSE(*none);
  for (std::uint64_t v = 1; v <= 4; ++v) {
    ASSERT_TRUE(saveSnapshotKeeping(*versionedView(v), SensorModel{}, Backend::kGrid, path, 3));
  }
  // Generations: path = 4, path.1 = 3, path.2 = 2; nothing older, no path.new left behind.
  for (int g = 0; g < 3; ++g) {
    auto loaded = loadSnapshot(snapshotGeneration(path, g), Backend::kGrid, 0.1);
    ASSERT_TRUE(loaded) << g;
    EXPECT_EQ(loaded->version, 4U - static_cast<unsigned>(g));
  }
  EXPECT_FALSE(std::filesystem::exists(snapshotGeneration(path, 3)));
  EXPECT_FALSE(std::filesystem::exists(snapshotGeneration(path, -1)));

  // A truncated newest file: the one before is loaded, and the reason is given.
  std::filesystem::resize_file(path, std::filesystem::file_size(path) - 7);
  auto resumed = loadNewestSnapshot(path, 3, Backend::kGrid, 0.1);
  ASSERT_TRUE(resumed && *resumed);
  EXPECT_EQ((*resumed)->snapshot.version, 3U);
  EXPECT_EQ((*resumed)->file, snapshotGeneration(path, 1));
  ASSERT_EQ((*resumed)->skipped.size(), 1U);
  EXPECT_NE((*resumed)->skipped[0].find("map.dmap"), std::string::npos);

  // One flipped bit in a value: the CRC catches what the protobuf parser cannot.
  {
    std::fstream f(snapshotGeneration(path, 1), std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(-3, std::ios::end);
    char c = 0;
    f.get(c);
    f.seekp(-3, std::ios::end);
    f.put(static_cast<char>(c ^ 0x10));
  }
  auto crc = loadSnapshot(snapshotGeneration(path, 1), Backend::kGrid, 0.1);
  ASSERT_FALSE(crc);
  EXPECT_NE(crc.error().message.find("CRC"), std::string::npos) << crc.error().message;
  resumed = loadNewestSnapshot(path, 3, Backend::kGrid, 0.1);
  ASSERT_TRUE(resumed && *resumed);
  EXPECT_EQ((*resumed)->snapshot.version, 2U);
  EXPECT_EQ((*resumed)->skipped.size(), 2U);

  // A complete save not yet rotated (a crash between writing and renaming) is the newest.
  ASSERT_TRUE(
      saveSnapshot(*versionedView(9), SensorModel{}, Backend::kGrid, snapshotGeneration(path, -1)));
  resumed = loadNewestSnapshot(path, 3, Backend::kGrid, 0.1);
  ASSERT_TRUE(resumed && *resumed);
  EXPECT_EQ((*resumed)->snapshot.version, 9U);

  // Nothing readable: an error naming every file.
  for (int g = -1; g < 3; ++g) std::ofstream(snapshotGeneration(path, g)) << "junk";
  auto broken = loadNewestSnapshot(path, 3, Backend::kGrid, 0.1);
  ASSERT_FALSE(broken);
  EXPECT_NE(broken.error().message.find("map.dmap.2"), std::string::npos);
  EXPECT_FALSE(saveSnapshotKeeping(*versionedView(1), SensorModel{}, Backend::kGrid, path, 0));
}

// A snapshot at another resolution is the map, not a corrupt
// file: resuming stops with the way out (before: "no readable snapshot", or worse an older
// generation silently resumed).
TEST(SnapshotGenerations, AnotherResolutionIsRefusedNotSkipped) {
  test::TempDir dir;
  const auto path = dir.path() / "map.dmap";
  for (std::uint64_t v = 1; v <= 2; ++v) {
    ASSERT_TRUE(saveSnapshotKeeping(*versionedView(v), SensorModel{}, Backend::kGrid, path, 3));
  }
  auto refused = loadNewestSnapshot(path, 3, Backend::kGrid, 0.2);  // saved at 0.1 m
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("map.resolution_m is 0.2"), std::string::npos)
      << refused.error().message;
  EXPECT_NE(refused.error().message.find("mapped at 0.1"), std::string::npos);
  auto resumed = loadNewestSnapshot(path, 3, Backend::kGrid, 0.1);
  ASSERT_TRUE(resumed && *resumed);
  EXPECT_EQ((*resumed)->snapshot.version, 2U);
}

struct KindCase {
  std::string kind;  // "log_odds" or a kernel method name
  Backend backend;
};

class OctomapFilesOfEveryKind : public ::testing::TestWithParam<KindCase> {};

/// The map a server with this kind and backend holds after two scans.
std::shared_ptr<const MapView> serverMap(const KindCase& c, double resolution) {
  server::IngestOptions options;
  options.engine.backend = c.backend;
  options.engine.resolution_m = resolution;
  options.engine.max_range_m = 6.0;
  if (c.kind != "log_odds") {
    auto method = kernel::parseKernelMethod(c.kind);
    EXPECT_TRUE(method) << c.kind;
    options.engine.kernel = *method;
  }
  auto pipeline = server::Ingest::create(options);
  EXPECT_TRUE(pipeline) << pipeline.error().message;
  (*pipeline)->start();
  for (int s = 0; s < 2; ++s) {
    RawScan scan;
    scan.sensor_id = "lidar";
    scan.seq = static_cast<std::uint64_t>(s) + 1;
    scan.t_world_sensor = {0.4 * s, 0.1, 0.0};
    const PointCloud points = test::adversarialScan(resolution, Point3f::Zero(), 1500, 6.0, s);
    for (const Point3f& p : points) scan.xyz.insert(scan.xyz.end(), {p.x(), p.y(), p.z()});
    (*pipeline)->submit(std::move(scan));
    for (int i = 0; i < 600 && (*pipeline)->counters().integrated <= static_cast<unsigned>(s);
         ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  EXPECT_EQ((*pipeline)->counters().integrated, 2U);
  (*pipeline)->stop();
  return (*pipeline)->view();
}

TEST_P(OctomapFilesOfEveryKind, OtAndBtAreReadByOctomapWithEveryCell) {
  const KindCase c = GetParam();
  constexpr double kResolution = 0.1;
  test::TempDir dir;
  const auto view = serverMap(c, kResolution);
  ASSERT_GT(view->knownCells(), 1000U);
  const SensorModel model{};
  ASSERT_TRUE(saveSnapshot(*view, model, c.backend, dir.path() / "m.ot"));
  ASSERT_TRUE(saveSnapshot(*view, model, c.backend, dir.path() / "m.bt"));

  std::unique_ptr<octomap::AbstractOcTree> abstract(
      octomap::AbstractOcTree::read((dir.path() / "m.ot").string()));
  ASSERT_NE(abstract, nullptr);
  EXPECT_EQ(abstract->getTreeType(), "OcTree");
  EXPECT_DOUBLE_EQ(abstract->getResolution(), kResolution);
  auto* tree = dynamic_cast<octomap::OcTree*>(abstract.get());
  ASSERT_NE(tree, nullptr);
  octomap::OcTree bt(0.5);
  ASSERT_TRUE(bt.readBinary((dir.path() / "m.bt").string()));
  EXPECT_DOUBLE_EQ(bt.getResolution(), kResolution);

  std::size_t cells = 0, beyond_clamps = 0;
  view->forEachKnown([&](const VoxelKey& k, float v) {
    ++cells;
    const octomap::OcTreeKey key(k.x, k.y, k.z);
    const octomap::OcTreeNode* node = tree->search(key);
    ASSERT_NE(node, nullptr);
    EXPECT_EQ(node->getLogOdds(), v);  // kernel maps: logit(p), so getOccupancy() is p
    EXPECT_NEAR(node->getOccupancy(), 1.0 / (1.0 + std::exp(-static_cast<double>(v))), 1e-9);
    if (v > model.clampMax() || v < model.clampMin()) ++beyond_clamps;
    const octomap::OcTreeNode* binary = bt.search(key);
    ASSERT_NE(binary, nullptr);
    EXPECT_EQ(bt.isNodeOccupied(binary), v > 0.0F);
  });
  tree->expand();
  EXPECT_EQ(tree->getNumLeafNodes(), cells);  // no cell more in the file
  if (c.kind == "log_odds") {
    EXPECT_EQ(beyond_clamps, 0U);
  } else {
    EXPECT_GT(beyond_clamps, 0U) << "expected kernel probabilities beyond OctoMap's clamps";
  }
}

INSTANTIATE_TEST_SUITE_P(
    Kinds, OctomapFilesOfEveryKind,
    ::testing::Values(KindCase{"log_odds", Backend::kGrid}, KindCase{"log_odds", Backend::kOctree},
                      KindCase{"akimap", Backend::kGrid}, KindCase{"bgk", Backend::kGrid},
                      KindCase{"bgkl", Backend::kGrid}, KindCase{"akimap_rays", Backend::kGrid},
                      KindCase{"akimap_rays", Backend::kOctree}),
    [](const ::testing::TestParamInfo<KindCase>& param_info) {
      return param_info.param.kind +
             (param_info.param.backend == Backend::kGrid ? "_grid" : "_octree");
    });

// A dense map's snapshot keeps its kernel evidence, so a restart resumes the kernel
// map itself: the resumed pipeline's map, and its update by the next scan, equal the original's
// bit for bit. A restart from the probabilities alone (the control) does not.
RawScan kernelScan(std::uint64_t seq) {
  const Point3f origin(0.1F * static_cast<float>(seq), 0.05F, 0.3F);
  const PointCloud cloud = test::adversarialScan(0.2, Point3f::Zero(), 1500, 6.0, 1000 + seq);
  RawScan raw;
  raw.seq = seq;
  raw.t_world_sensor = {origin.x(), origin.y(), origin.z()};
  for (const auto& p : cloud) raw.xyz.insert(raw.xyz.end(), {p.x(), p.y(), p.z()});
  return raw;
}

void integrateAll(server::Ingest& pipeline, const std::vector<RawScan>& raws) {
  const std::uint64_t before = pipeline.counters().integrated;
  for (const RawScan& raw : raws) pipeline.submit(raw);
  for (int i = 0; i < 1000 && pipeline.counters().integrated < before + raws.size(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(pipeline.counters().integrated, before + raws.size());
}

void expectSameEvidence(const kernel::KernelEvidence& a, const kernel::KernelEvidence& b) {
  EXPECT_EQ(a.scans, b.scans);
  ASSERT_EQ(a.keys.size(), b.keys.size());
  EXPECT_TRUE(std::equal(a.keys.begin(), a.keys.end(), b.keys.begin()));
  EXPECT_EQ(a.alpha, b.alpha);  // bit for bit
  EXPECT_EQ(a.beta, b.beta);
}

TEST(Snapshot, ADenseMapResumesItsKernelEvidenceAndTheNextScanUpdatesItAlike) {
  test::TempDir dir;
  const server::IngestOptions options{.engine = {.resolution_m = 0.2,
                                                 .max_range_m = 5.0,
                                                 .kernel = kernel::KernelMethod::kAkimapRays},
                                      .threads = 2};
  auto original = server::Ingest::create(options);
  ASSERT_TRUE(original) << original.error().message;
  (*original)->start();
  integrateAll(**original, {kernelScan(1), kernelScan(2)});
  const server::Ingest::SavedState saved = (*original)->savedState();
  ASSERT_TRUE(saved.kernel);
  ASSERT_GT(saved.kernel->keys.size(), 1000U);
  EXPECT_EQ(saved.kernel->scans, 2U);
  const auto file = dir.path() / "dense.dmap";
  const SensorModel model(options.engine.sensor);
  ASSERT_TRUE(saveSnapshot(*saved.view, model, Backend::kGrid, file, &*saved.kernel));

  auto loaded = loadSnapshot(file, Backend::kGrid, 0.2);
  ASSERT_TRUE(loaded) << loaded.error().message;
  ASSERT_TRUE(loaded->kernel);
  expectSameEvidence(*loaded->kernel, *saved.kernel);
  EXPECT_EQ(loaded->version, saved.view->version());

  // The same file without its evidence: the control.
  auto plain = loadSnapshot(file, Backend::kGrid, 0.2);
  ASSERT_TRUE(plain);
  auto resumed = server::Ingest::create(options, std::move(loaded->map), loaded->version);
  auto control = server::Ingest::create(options, std::move(plain->map), plain->version);
  ASSERT_TRUE(resumed && control);
  ASSERT_TRUE((*resumed)->restoreKernelEvidence(*loaded->kernel));
  expectSameEvidence(*(*resumed)->savedState().kernel, *saved.kernel);
  (*resumed)->start();
  (*control)->start();
  for (server::Ingest* p : {original->get(), resumed->get(), control->get()}) {
    integrateAll(*p, {kernelScan(3)});
  }
  const auto a = (*original)->savedState(), b = (*resumed)->savedState(),
             c = (*control)->savedState();
  expectSameEvidence(*b.kernel, *a.kernel);
  EXPECT_EQ(b.view->version(), a.view->version());
  EXPECT_EQ(b.view->knownCells(), a.view->knownCells());
  std::size_t differ = 0, control_differ = 0;
  a.view->forEachKnown([&](const VoxelKey& k, float v) {
    differ += b.view->logOdds(k) != v;
    control_differ += c.view->logOdds(k) != v;
  });
  EXPECT_EQ(differ, 0U);
  EXPECT_GT(control_differ, 100U);  // without the evidence the next scan's update differs

  // Evidence of another kind, or for a log-odds map, is refused.
  auto other = *loaded->kernel;
  other.method = kernel::KernelMethod::kBgk;
  auto fresh = server::Ingest::create(options);
  EXPECT_FALSE((*fresh)->restoreKernelEvidence(other));
  auto log_odds = server::Ingest::create({.engine = {.resolution_m = 0.2, .max_range_m = 5.0}});
  EXPECT_FALSE((*log_odds)->restoreKernelEvidence(*loaded->kernel));
  for (server::Ingest* p : {original->get(), resumed->get(), control->get()}) p->stop();
}

TEST(Snapshot, KernelEvidenceCutOrCorruptedIsRefused) {
  test::TempDir dir;
  GridMap map(0.2, SensorModel{});
  map.setLogOdds(VoxelKey{1, 2, 3}, 1.0F);
  kernel::KernelEvidence e;
  e.resolution_m = 0.2;
  e.scans = 7;
  e.keys = {VoxelKey{1, 2, 3}, VoxelKey{9, 9, 9}};
  e.alpha = {0.5, 0.0};
  e.beta = {0.25, 3.0};
  const auto file = dir.path() / "k.dmap";
  ASSERT_TRUE(saveSnapshot(*MapView::fromMap(map, 4), map.sensorModel(), Backend::kGrid, file, &e));
  auto loaded = loadSnapshot(file, Backend::kGrid, 0.2);
  ASSERT_TRUE(loaded && loaded->kernel);
  expectSameEvidence(*loaded->kernel, e);
  // No prefix parses, not even one that ends where the log-odds cells do.
  const std::string whole = expectEveryCutRefused(file, dir.path());
  // A flipped bit in a beta value (the last 8 bytes before the CRC field's 5, which the map
  // kind's field follows: a 2-byte tag, a length byte, "akimap_rays") fails the CRC.
  std::string flipped = whole;
  const std::size_t beta_end = flipped.size() - (3 + std::string("akimap_rays").size()) - 5;
  flipped[beta_end - 2] = static_cast<char>(flipped[beta_end - 2] ^ 0x10);
  std::ofstream(dir.path() / "flip.dmap", std::ios::binary) << flipped;
  auto corrupt = loadSnapshot(dir.path() / "flip.dmap", Backend::kGrid, 0.0);
  ASSERT_FALSE(corrupt);
  EXPECT_NE(corrupt.error().message.find("kernel evidence"), std::string::npos)
      << corrupt.error().message;
}

}  // namespace
}  // namespace densemap
