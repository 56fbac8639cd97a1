// A daemon that drives for months: with map.keep_radius_m the server's resident memory stays
// flat over a long simulated drive, while without it the map (and RSS) grows with the distance
// driven. densemap-server as a process on loopback, one DDS domain per test.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"

namespace densemap {
namespace {

using namespace std::chrono_literals;

struct Sample {
  std::uint64_t scans, rss, map_bytes, known, evicted_blocks;
};

/// Publishes each scan and waits for its map event; every `every` scans, the server's status.
std::vector<Sample> drive(Client& client, const std::vector<RawScan>& raws, std::size_t every) {
  std::vector<Sample> samples;
  for (const RawScan& raw : raws) {
    EXPECT_TRUE(client.publishScan(raw));
    const bool seen = test::waitForScanEvent(client, raw.seq);
    EXPECT_TRUE(seen) << "scan " << raw.seq;
    if (!seen) break;
    if (raw.seq % every == 0) {
      // Status comes once a second: wait for one that counts this scan.
      for (const auto deadline = std::chrono::steady_clock::now() + 5s;
           std::chrono::steady_clock::now() < deadline;) {
        auto s = client.status();
        if (s && s->integrated >= raw.seq) {
          samples.push_back(
              {raw.seq, s->rss_bytes, s->memory_bytes, s->known_cells, s->evicted_blocks});
          break;
        }
        std::this_thread::sleep_for(50ms);
      }
    }
  }
  return samples;
}

/// A drive along a street, a 16-beam scan every 5 m: `default_scans` scans, or
/// DENSEMAP_LONG_DRIVE_SCANS (at least 40) for longer drives. `scene` receives the street.
std::vector<RawScan> streetDrive(const std::filesystem::path& dir, int default_scans,
                                 std::string& scene) {
  const char* env = std::getenv("DENSEMAP_LONG_DRIVE_SCANS");
  const int scans = env != nullptr ? std::max(40, std::atoi(env)) : default_scans;
  SequenceOptions o;
  o.scene = "street:" + std::to_string(std::max(1000, 5 * scans));
  o.sensor = "vlp16";
  o.scans = scans;
  o.ground_truth_resolution_m = 0;
  scene = o.scene;
  auto raws = test::simulatedRawScans(dir, o, "lidar");
  EXPECT_EQ(raws.size(), static_cast<std::size_t>(scans));
  return raws;
}

TEST(BoundedMemory, ALongDriveWithAKeepRadiusKeepsRssFlatWithoutItRssGrows) {
  test::TempDir dir;
  std::string scene;  // a 1 km street by default
  const auto raws = streetDrive(dir.path(), 200, scene);
  const int scans = static_cast<int>(raws.size());
  const std::string limits = "pipeline { max_abs_position_m: 60000 }\n";
  std::vector<Sample> windowed, unbounded;
  for (const bool window : {true, false}) {
    const std::uint32_t domain = window ? 174 : 175;
    const std::filesystem::path run = dir.path() / (window ? "window" : "unbounded");
    std::filesystem::create_directories(run);
    test::ServerProcess server(run, domain, limits, false, 0, window ? "keep_radius_m: 40" : "");
    auto client = test::connectClient(domain);
    ASSERT_TRUE(client);
    (window ? windowed : unbounded) = drive(*client, raws, 20);
  }
  ASSERT_GE(windowed.size(), 4U);
  ASSERT_EQ(windowed.size(), unbounded.size());
  // After the first quarter (the window has filled): flat within 10%.
  const std::size_t from = windowed.size() / 4;
  auto rss = [](const Sample& s) { return s.rss; };
  std::vector<std::uint64_t> w, u;
  for (std::size_t i = from; i < windowed.size(); ++i) {
    w.push_back(rss(windowed[i]));
    u.push_back(rss(unbounded[i]));
  }
  const auto [wmin, wmax] = std::minmax_element(w.begin(), w.end());
  std::printf("long drive, %d scans over %s m, RSS after the first quarter (MiB):\n", scans,
              scene.substr(7).c_str());
  std::printf("  keep_radius_m 40: %.1f .. %.1f (map %.1f MiB, %ju cells, %ju blocks evicted)\n",
              *wmin / 1048576.0, *wmax / 1048576.0, windowed.back().map_bytes / 1048576.0,
              static_cast<std::uintmax_t>(windowed.back().known),
              static_cast<std::uintmax_t>(windowed.back().evicted_blocks));
  std::printf("  no window:        %.1f .. %.1f (map %.1f MiB, %ju cells)\n", u.front() / 1048576.0,
              u.back() / 1048576.0, unbounded.back().map_bytes / 1048576.0,
              static_cast<std::uintmax_t>(unbounded.back().known));
  EXPECT_LE(static_cast<double>(*wmax), 1.10 * static_cast<double>(*wmin));
  EXPECT_GT(windowed.back().evicted_blocks, 1000U);
  // The control: without the window the same drive grows the map and the process.
  EXPECT_GT(unbounded.back().map_bytes, 3 * windowed.back().map_bytes);
  EXPECT_GT(static_cast<double>(u.back()), 1.3 * static_cast<double>(u.front()));
}

// A dense map evicts with the grid, so a kernel map kind keeps the same promise: flat
// RSS.
TEST(BoundedMemory, ADenseMapWithAKeepRadiusKeepsRssFlat) {
  test::TempDir dir;
  // RSS within 10% over the second half. Blocks that a kernel's box overlapped without
  // reaching a cell, kept by the kernel map, would make RSS creep (KernelMapMemory's unit test
  // guards that). Without eviction the kernel map alone grows several times over.
  std::string scene;
  const auto raws = streetDrive(dir.path(), 300, scene);
  const int scans = static_cast<int>(raws.size());
  test::ServerProcess server(dir.path(), 165, "pipeline { max_abs_position_m: 60000 }\n", false, 0,
                             "keep_radius_m: 40 kind: \"akimap_rays\"");
  auto client = test::connectClient(165);
  ASSERT_TRUE(client);
  const std::vector<Sample> windowed = drive(*client, raws, 20);
  ASSERT_GE(windowed.size(), 4U);
  std::vector<std::uint64_t> w;
  for (std::size_t i = windowed.size() / 2; i < windowed.size(); ++i) w.push_back(windowed[i].rss);
  const auto [wmin, wmax] = std::minmax_element(w.begin(), w.end());
  std::printf(
      "akimap_rays, long drive, %d scans, keep_radius_m 40: RSS %.1f .. %.1f MiB over "
      "the second half (%ju cells, %ju blocks evicted)\n",
      scans, *wmin / 1048576.0, *wmax / 1048576.0,
      static_cast<std::uintmax_t>(windowed.back().known),
      static_cast<std::uintmax_t>(windowed.back().evicted_blocks));
  for (const Sample& s : windowed)
    std::printf("  scan %ju: RSS %.1f MiB, %ju cells\n", static_cast<std::uintmax_t>(s.scans),
                s.rss / 1048576.0, static_cast<std::uintmax_t>(s.known));
  EXPECT_LE(static_cast<double>(*wmax), 1.10 * static_cast<double>(*wmin));
  EXPECT_GT(windowed.back().evicted_blocks, 1000U);
  std::uint64_t most = 0, least = ~std::uint64_t{0};
  for (std::size_t i = windowed.size() / 4; i < windowed.size(); ++i) {
    most = std::max(most, windowed[i].known);
    least = std::min(least, windowed[i].known);
  }
  EXPECT_LE(static_cast<double>(most), 1.5 * static_cast<double>(least));  // the window's map
}

}  // namespace
}  // namespace densemap
