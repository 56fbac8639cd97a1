#pragma once

#include <cstdint>
#include <string>

namespace densemap {

/// What a mapping pipeline did with one sensor's scans (its server's status, per sensor).
struct SensorCounters {
  std::string sensor_id;
  std::uint64_t received = 0;    // submitted to the pipeline
  std::uint64_t integrated = 0;  // in the map
  std::uint64_t dropped = 0;     // overwritten in the latest-wins queue (integration behind)
  std::uint64_t rejected = 0;    // failed validation
  /// Sequence numbers skipped between consecutive received scans: scans lost before the
  /// pipeline saw them (e.g. overwritten in the DDS reader's history) or never sent.
  std::uint64_t seq_gaps = 0;
  std::uint64_t last_seq = 0;

  bool operator==(const SensorCounters&) const = default;
};

}  // namespace densemap
