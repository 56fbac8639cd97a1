#pragma once

// The scans of a simulated sequence, as the exactness tests integrate them (needs densemap::sim).
#include <filesystem>
#include <vector>

#include "densemap/sim/sequence.hpp"
#include "exactness_harness.hpp"

namespace densemap::test {

/// Every scan of the simulated sequence `options` (written into `dir`), in the world frame.
inline std::vector<WorldScan> simulatedWorldScans(const SequenceOptions& options,
                                                  const std::filesystem::path& dir) {
  EXPECT_TRUE(writeSimulatedSequence(options, dir));
  auto source = openScanSource(dir);
  EXPECT_TRUE(source);
  if (!source) return {};
  return loadWorldScans(**source, 0, static_cast<std::size_t>(options.scans));
}

}  // namespace densemap::test
