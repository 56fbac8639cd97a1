// A daemon that is killed (SIGKILL, no shutdown snapshot) or finds a damaged snapshot: it keeps
// the last 3 snapshot files, never leaves a corrupt one, and resumes from the newest readable.
// densemap-server as a separate process on loopback, one DDS domain per test.
#include <gtest/gtest.h>

#include <sys/socket.h>
#include <sys/un.h>

#include <random>
#include <thread>

#include "densemap/client/client.hpp"
#include "densemap/client/testing.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/sim/sequence.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/server_clients.hpp"
#include "densemap/test_support/server_process.hpp"

namespace densemap {
namespace {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

std::vector<RawScan> simulatedScans(const fs::path& dir, int n, const std::string& sensor) {
  SequenceOptions o;
  o.scene = "outdoor";
  o.sensor = sensor;
  o.scans = n;
  o.ground_truth_resolution_m = 0;
  return test::simulatedRawScans(dir, o, "lidar");
}

std::unique_ptr<Client> connect(std::uint32_t domain) { return test::connectClient(domain); }

/// Starts a server on `dir`; the map it resumes is `expected` at `version`, cell for cell.
/// Returns the server's log.
std::string expectRestartServes(const fs::path& dir, std::uint32_t domain, std::uint64_t version,
                                const OccupancyMap& expected) {
  test::ServerProcess server(dir, domain, "", true);
  auto client = connect(domain);
  EXPECT_TRUE(client);
  if (!client) return server.log();
  auto fetched = client->fetchMap(version);
  EXPECT_TRUE(fetched) << fetched.error().message;
  if (!fetched) return server.log();
  EXPECT_EQ(fetched->version(), version);
  EXPECT_EQ(diffMaps(testing::gridOf(*fetched), expected).differing(), 0U);
  return server.log();
}

/// Every snapshot file present is complete; returns the newest's version.
std::uint64_t expectSnapshotsIntact(const fs::path& path) {
  for (int g = -1; g < 3; ++g) {
    const fs::path file = snapshotGeneration(path, g);
    if (!fs::exists(file)) continue;
    auto loaded = loadSnapshot(file, Backend::kGrid, 0.2);
    EXPECT_TRUE(loaded) << loaded.error().message;
  }
  auto newest = loadNewestSnapshot(path, 3, Backend::kGrid, 0.2);
  EXPECT_TRUE(newest && *newest);
  return newest && *newest ? (*newest)->snapshot.version : 0;
}

TEST(Recovery, KillNineAfterAnAutosaveLosesNothingAndTheRestartResumesIt) {
  constexpr std::uint32_t kDomain = 161;
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 4, "vlp16");
  const fs::path path = dir.path() / "map.dmap";
  {
    test::ServerProcess server(dir.path(), kDomain, "", true, /*autosave_s=*/0.3);
    auto client = connect(kDomain);
    ASSERT_TRUE(client);
    test::replayScans(*client, raws);
    // At least one autosave after the last scan: the period stretches with the save's own
    // duration (4x), so on a loaded machine it can take longer than a fixed wait.
    for (int i = 0; i < 100; ++i) {
      std::this_thread::sleep_for(100ms);
      auto newest = loadNewestSnapshot(path, 3, Backend::kGrid, 0.2);
      if (newest && *newest && (*newest)->snapshot.version == 4) break;
    }
    server.kill9();
  }
  EXPECT_EQ(expectSnapshotsIntact(path), 4U);
  auto saved = loadNewestSnapshot(path, 3, Backend::kGrid, 0.2);
  ASSERT_TRUE(saved && *saved);

  const std::string log = expectRestartServes(dir.path(), kDomain, 4, *(*saved)->snapshot.map);
  EXPECT_NE(log.find("resumed"), std::string::npos) << log;
}

TEST(Recovery, KillNineAtRandomMomentsWhileMappingAndSavingLeavesNoCorruptFile) {
  constexpr std::uint32_t kDomain = 162;
  test::TempDir dir;
  // A 64-beam street: snapshots of a few MB, so writes take long enough to be interrupted.
  const auto raws = simulatedScans(dir.path(), 3, "hdl64");
  const fs::path path = dir.path() / "map.dmap";
  constexpr double kAutosave = 0.05;  // saves take a good share of the time: kills land in them
  std::mt19937 rng(3);
  int interrupted = 0;  // rounds that left a partial write (.new.tmp) or an unrotated .new
  std::uint64_t seq = 0, worst_lost = 0;
  for (int round = 0; round < 10; ++round) {
    SCOPED_TRACE("round " + std::to_string(round));
    test::ServerProcess server(dir.path(), kDomain, "", true, kAutosave);
    auto client = connect(kDomain);
    ASSERT_TRUE(client);
    // Scans keep coming (the map changes, so autosaves write) until the kill.
    std::uint64_t last_version = 0;
    const auto kill_at =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(800 + rng() % 1200);
    while (std::chrono::steady_clock::now() < kill_at) {
      RawScan raw = raws[seq % raws.size()];
      raw.seq = ++seq;
      ASSERT_TRUE(client->publishScan(raw));
      std::this_thread::sleep_for(50ms);
      client->pollEvents([&](const MapEventInfo& e) { last_version = e.new_version; });
    }
    server.kill9();
    const fs::path fresh = snapshotGeneration(path, -1);
    bool partial = false;  // a temporary file of a save (path.new.tmp.XXXXXX) left behind
    for (const auto& entry : fs::directory_iterator(dir.path())) {
      partial |= entry.path().filename().string().starts_with(fresh.filename().string() + ".tmp.");
    }
    interrupted += fs::exists(fresh) || partial;
    const std::uint64_t saved = expectSnapshotsIntact(path);
    EXPECT_GT(saved, 0U);
    worst_lost = std::max(worst_lost, last_version > saved ? last_version - saved : 0);
  }
  std::printf(
      "kill -9 rounds: 10 while mapping at 20 Hz with autosave every %.2f s; kills that "
      "interrupted a snapshot write or rotation: %d; at most %ju versions (scans) lost; "
      "snapshot %ju bytes\n",
      kAutosave, interrupted, static_cast<std::uintmax_t>(worst_lost),
      static_cast<std::uintmax_t>(fs::file_size(path)));
  // At 20 Hz, one autosave period (plus the save itself and the events in flight) is a handful
  // of scans; a lost autosave would show as many more.
  EXPECT_LE(worst_lost, 20U);
  auto newest = loadNewestSnapshot(path, 3, Backend::kGrid, 0.2);
  ASSERT_TRUE(newest && *newest);
  (void)expectRestartServes(dir.path(), kDomain, (*newest)->snapshot.version,
                            *(*newest)->snapshot.map);
}

TEST(Recovery, ATruncatedNewestSnapshotFallsBackToThePreviousOneWithAWarning) {
  constexpr std::uint32_t kDomain = 163;
  test::TempDir dir;
  const auto raws = simulatedScans(dir.path(), 4, "vlp16");
  const fs::path path = dir.path() / "map.dmap";
  {
    test::ServerProcess server(dir.path(), kDomain, "", true);
    auto client = connect(kDomain);
    ASSERT_TRUE(client);
    test::replayScans(*client, {raws[0], raws[1]});
    ASSERT_TRUE(client->save());  // version 2
    test::replayScans(*client, {raws[2], raws[3]});
    EXPECT_EQ(server.stop(), 0);  // version 4, the newest
  }
  auto previous = loadSnapshot(snapshotGeneration(path, 1), Backend::kGrid, 0.2);
  ASSERT_TRUE(previous);
  EXPECT_EQ(previous->version, 2U);
  fs::resize_file(path, fs::file_size(path) / 2);

  const std::string log = expectRestartServes(dir.path(), kDomain, 2, *previous->map);
  EXPECT_NE(log.find("warning: skipping an unreadable snapshot"), std::string::npos) << log;
  EXPECT_NE(log.find("map.dmap.1"), std::string::npos) << log;
}

/// systemd's notify protocol, as systemd runs the unit (Type=notify, WatchdogSec): a datagram
/// socket in $NOTIFY_SOCKET, the period in $WATCHDOG_USEC.
TEST(Daemon, TellsSystemdItIsReadyPingsTheWatchdogAndSaysWhenItStops) {
#ifndef DENSEMAP_HAVE_SYSTEMD
  GTEST_SKIP() << "built without libsystemd (libsystemd-dev): no notify protocol";
#endif
  test::TempDir dir;
  const std::string socket_path = (dir.path() / "notify.sock").string();
  const int fd = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(socket_path.size(), sizeof(addr.sun_path));
  std::strcpy(addr.sun_path, socket_path.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
  const timeval wait{0, 200'000};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &wait, sizeof(wait));
  ::setenv("NOTIFY_SOCKET", socket_path.c_str(), 1);
  ::setenv("WATCHDOG_USEC", "400000", 1);  // pings every 0.2 s
  std::string messages;
  {
    test::ServerProcess server(dir.path(), 164);
    ::unsetenv("NOTIFY_SOCKET");
    ::unsetenv("WATCHDOG_USEC");
    const auto until = std::chrono::steady_clock::now() + 3s;
    char buffer[512];
    while (std::chrono::steady_clock::now() < until) {
      const ssize_t n = ::recv(fd, buffer, sizeof(buffer), 0);
      if (n > 0) messages.append(buffer, static_cast<std::size_t>(n)).append("|");
    }
    EXPECT_EQ(server.stop(), 0);
    for (int i = 0; i < 10; ++i) {
      const ssize_t n = ::recv(fd, buffer, sizeof(buffer), 0);
      if (n > 0) messages.append(buffer, static_cast<std::size_t>(n)).append("|");
    }
  }
  ::close(fd);
  EXPECT_NE(messages.find("READY=1"), std::string::npos) << messages;
  std::size_t pings = 0;
  for (std::size_t at = messages.find("WATCHDOG=1"); at != std::string::npos;
       at = messages.find("WATCHDOG=1", at + 1)) {
    ++pings;
  }
  EXPECT_GE(pings, 5U) << messages;  // about 3 s / 0.2 s, less start-up
  EXPECT_NE(messages.find("STOPPING=1"), std::string::npos) << messages;
}

}  // namespace
}  // namespace densemap
