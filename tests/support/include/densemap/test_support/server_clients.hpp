#pragma once
// Helpers of the tests that run densemap-server as a process (header-only: for targets that
// link densemap_client and densemap::sim).
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "densemap/client/client.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/sim/sequence.hpp"

namespace densemap::test {

/// A client on `domain` (loopback) that has found the server; null (and a test failure) if not.
inline std::unique_ptr<Client> connectClient(std::uint32_t domain, bool subscribe_deltas = false) {
  using namespace std::chrono_literals;
  auto client =
      Client::create({.domain_id = domain, .timeout = 10s, .subscribe_deltas = subscribe_deltas});
  EXPECT_TRUE(client) << client.error().message;
  if (!client) return nullptr;
  auto ok = (*client)->waitForServer();
  EXPECT_TRUE(ok) << ok.error().message;
  return std::move(*client);
}

/// Whether `client` sees the map event of scan `seq` within 20 s (it polls map/events).
inline bool waitForScanEvent(Client& client, std::uint64_t seq) {
  using namespace std::chrono_literals;
  bool seen = false;
  for (const auto deadline = std::chrono::steady_clock::now() + 20s;
       !seen && std::chrono::steady_clock::now() < deadline;) {
    client.pollEvents([&](const MapEventInfo& e) { seen = seen || e.scan_seq == seq; });
    if (!seen) std::this_thread::sleep_for(2ms);
  }
  return seen;
}

/// Publishes each scan and waits for its map event (a test failure if one never comes).
inline void replayScans(Client& client, const std::vector<RawScan>& raws) {
  for (const RawScan& raw : raws) {
    ASSERT_TRUE(client.publishScan(raw));
    ASSERT_TRUE(waitForScanEvent(client, raw.seq)) << "scan " << raw.seq;
  }
}

/// A small simulated drive: `scans` VLP-16 scans of `columns` columns through the indoor scene,
/// no ground truth.
inline SequenceOptions smallIndoorDrive(int scans, int columns) {
  SequenceOptions o;
  o.scene = "indoor";
  o.sensor = "vlp16";
  o.columns = columns;
  o.scans = scans;
  o.ground_truth_resolution_m = 0;
  return o;
}

/// Writes a simulated sequence to `dir/data` and returns its scans as a sender publishes them
/// (seq 1, 2, ...; `sensor_id`).
inline std::vector<RawScan> simulatedRawScans(const std::filesystem::path& dir,
                                              const SequenceOptions& options,
                                              const std::string& sensor_id) {
  EXPECT_TRUE(writeSimulatedSequence(options, dir / "data"));
  auto source = openScanSource(dir / "data");
  std::vector<RawScan> raws;
  if (!source) return raws;
  for (std::size_t i = 0; i < (*source)->size(); ++i) {
    raws.push_back(toRawScan(*(*source)->load(i), i + 1, sensor_id));
  }
  return raws;
}

}  // namespace densemap::test
