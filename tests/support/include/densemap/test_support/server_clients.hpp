#pragma once
// Helpers of the tests that run densemap-server as a process (header-only: for targets that
// link densemap_client and densemap::sim).
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
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
